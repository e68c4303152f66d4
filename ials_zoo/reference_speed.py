"""The machine's speed on a fixed reference workload, so that wall-clocks can be compared.

A training run's wall-clock says as much about the machine, and about what else ran on it, as
about the method: the same run takes 2-4x longer on loaded cores. So every training run times
a fixed workload (:func:`measure`: interpreter work, small numpy algebra and a small torch
update, on one thread: what an env step and a PPO update are made of) at its start and at
every checkpoint, and records the timings (``training.reference``). Its wall-clock *in
reference seconds* is its seconds scaled by the machine's speed to the reference machine's
(:data:`REFERENCE_WORKLOAD_SECONDS`): what the run would have taken there, a figure that moves
far less between machines and loads than seconds do.

A run whose workload times moved by more than :data:`LOAD_TOLERANCE` (20%) between its
fastest and slowest measurement was *timed under load*: its wall-clock, in seconds or in
units, is not a quiet machine's. ``training.reference.machine`` names the processor, so a
comparison can say when two runs were timed on different machines.

The workload is versioned (:data:`WORKLOAD`): units of two versions are not compared.
"""

from __future__ import annotations

import os
import platform
import statistics
import time

import numpy as np

WORKLOAD = "ref-1"
"""The workload's version: change it whenever :func:`_workload` changes."""
REFERENCE_WORKLOAD_SECONDS = 0.0585
"""The workload's median seconds on the reference machine (the project's 2-core development
machine, an Intel Xeon of 2026, quiet: 0.0578-0.0637 s over 9 measurements)."""
LOAD_TOLERANCE = 0.20
"""Slowest / fastest workload time above 1 + this: the run was timed under load."""
REPEATS = 3  # one measurement: the median of three workloads (about 0.3 s on a 2026 core)
MAX_SAMPLES = 200  # a record's timings; a longer run keeps its first and its latest 199


def _interpreter(n: int = 100_000) -> int:
    counts: dict = {}
    total = 0
    for i in range(n):
        k = i % 97
        counts[k] = counts.get(k, 0) + i
        total += len(str(k))
    return total


def _arrays(n: int = 1_200) -> float:
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((64, 64)), rng.standard_normal(64)
    for _ in range(n):
        b = np.tanh(a @ b)
        a = a * 0.999 + 0.001
    return float(b.sum())


def _update(n: int = 40) -> float:
    import torch

    g = torch.Generator().manual_seed(0)
    x, y = torch.randn(512, 64, generator=g), torch.randn(512, 5, generator=g)
    net = torch.nn.Sequential(torch.nn.Linear(64, 64), torch.nn.Tanh(), torch.nn.Linear(64, 64), torch.nn.Tanh(),
                              torch.nn.Linear(64, 5))
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    loss = None
    for _ in range(n):
        opt.zero_grad()
        loss = ((net(x) - y) ** 2).mean()
        loss.backward()
        opt.step()
    return float(loss.detach())


def _workload() -> None:
    _interpreter()
    _arrays()
    _update()


def measure(repeats: int = REPEATS) -> float:
    """Seconds of one reference workload on this machine now (median of ``repeats``, after a
    warm-up), on one torch thread whatever the run uses; torch's random state and thread count
    are left as they were (a run's future must not depend on its measurements)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with torch.random.fork_rng(devices=[]):  # the layers' initialisation draws from torch's stream
            _update(2)  # warm-up: the first torch call pays for its kernels
            times = []
            for _ in range(max(int(repeats), 1)):
                start = time.perf_counter()
                _workload()
                times.append(time.perf_counter() - start)
    finally:
        torch.set_num_threads(threads)
    return statistics.median(times)


def processor_name() -> str:
    """The processor's model name (Linux's ``/proc/cpuinfo``), else what ``platform`` says."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown processor"


def machine() -> str:
    """The processor's name and core count, as a comparison names the machine."""
    return f"{processor_name()[:200]}, {os.cpu_count() or 0} cores"


class ReferenceLog:
    """A run's reference timings: one at its start, one at every checkpoint (off its clock),
    and the machines they were taken on (a run resumed on another machine names both)."""

    def __init__(self, record: dict | None = None):
        record = record if isinstance(record, dict) else {}
        self.samples = [float(s) for s in record.get("seconds", []) if isinstance(s, (int, float))]
        self.machines = [m for m in str(record.get("machine") or "").split("; ") if m]
        if record.get("workload", WORKLOAD) != WORKLOAD:  # a resume across versions starts anew
            self.samples, self.machines = [], []

    def sample(self) -> float:
        seconds = measure()
        if machine() not in self.machines:
            self.machines.append(machine())
        self.samples.append(round(seconds, 6))
        if len(self.samples) > MAX_SAMPLES:
            del self.samples[1]  # keep the first (the start) and the latest
        return seconds

    def record(self, wall_clock_seconds: float | None = None) -> dict:
        """``training.reference``: the workload, the machine, its timings and, given the run's
        wall-clock (training and AIPs), the same in reference seconds."""
        out = {"workload": WORKLOAD, "machine": "; ".join(self.machines or [machine()])[:1000],
               "seconds": list(self.samples)}
        if wall_clock_seconds is not None and self.samples:
            out["reference_seconds"] = reference_seconds(wall_clock_seconds, self.samples)
        out["under_load"] = under_load(out)
        return out


def reference_seconds(wall_clock_seconds: float, samples) -> float:
    """``wall_clock_seconds`` on a machine whose workload took ``samples`` seconds, as seconds
    of the reference machine."""
    return round(float(wall_clock_seconds) * REFERENCE_WORKLOAD_SECONDS / statistics.median(samples), 6)


def under_load(record: dict | None) -> bool:
    """Whether a ``training.reference`` record's timings moved by more than 20%."""
    samples = [float(s) for s in (record or {}).get("seconds", []) if isinstance(s, (int, float)) and s > 0]
    return len(samples) >= 2 and max(samples) / min(samples) > 1.0 + LOAD_TOLERANCE


def merged(records: list) -> dict | None:
    """The ``training.reference`` of seeds merged into one entry: every seed's timings, the
    machines named once each, the mean of their reference seconds, under load if any seed was;
    None unless every seed has one."""
    if not records or not all(of({"reference": r}) for r in records):
        return None
    if len({r.get("workload") for r in records}) != 1:  # timings of two workloads do not compare
        return None
    machines = list(dict.fromkeys(r["machine"] for r in records))
    seconds = [s for r in records for s in r["seconds"]]
    return {"workload": records[0]["workload"], "machine": "; ".join(machines)[:1000],
            "seconds": seconds[:1000] + seconds[1000:][-1000:],
            "reference_seconds": round(sum(r["reference_seconds"] for r in records) / len(records), 3),
            "under_load": any(r["under_load"] for r in records)}


def of(training: dict | None) -> dict | None:
    """A training record's ``reference`` (None for runs from before the reference workload)."""
    ref = (training or {}).get("reference")
    return ref if isinstance(ref, dict) and isinstance(ref.get("reference_seconds"), (int, float)) else None


__all__ = ["LOAD_TOLERANCE", "REFERENCE_WORKLOAD_SECONDS", "WORKLOAD", "ReferenceLog", "machine", "measure", "merged", "of",
           "processor_name",
           "reference_seconds", "under_load"]
