"""Speed of the traffic simulators: raw SUMO, the GS and the LS (steps per second).

Usage::

    ials-zoo sumo-bench [--episodes 3] [--repeats 3]
    ials-zoo sumo-bench --breakdown

Prints the best of ``repeats`` runs (the machine is shared; the best run is the least
disturbed one), as wall-clock steps/s and as steps per CPU-second of this process (less
sensitive to other load; not meaningful for the worker case, whose SUMO runs in another
process), for: raw ``simulationStep()`` of the 5 x 5 grid, the GS with one learner
(``tls_12``, the others actuated) in-process and in a worker, the GS with all 25 learners,
and the LS (``tls_12``) with 1, 8 and 64 copies (env-steps/s = copies x steps/s). Actions:
switch w.p. 0.1; LS influences: each bit 1 w.p. 0.1 (the untrained AIP).

``--breakdown`` instead splits the LS step (in-process) into its parts, in CPU ms per step
and CPU us per copy-step: lights + ``vehicle.add``, SUMO's ``simulationStep``, the lane
reads, the rest (the LS's checks, turn draws, observation). Measured here (quiet machine):
SUMO's own step is ~45 % of the LS step at 1 copy and ~65 % at 64, and grows faster than
the number of copies (~25 us per copy at 8 copies, ~40 at 64, ~50 at 128: memory, not
Python); a ``vehicle.add`` costs ~20 us inside SUMO (device set-up per car); the lane reads
~1 us per car seen (libsumo call cost; subscriptions and numpy versions measured no faster).
"""

from __future__ import annotations

import time

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.sumo.lease import SimulationBusyError, import_libsumo
from ials_zoo.traffic.env import TrafficGridEnv
from ials_zoo.traffic.local import TrafficLocalSimulator


def _gs(learners, episodes, backend, seed=0, raw=False):
    env = TrafficGridEnv(learners=learners, backend=backend)
    rng = np.random.default_rng(seed)
    steps = 0
    try:
        env.reset(seed=seed)  # starts the worker, if any, outside the timing
        t0, c0 = time.perf_counter(), time.process_time()
        for ep in range(episodes):
            env.reset(seed=seed + ep)
            if raw:
                libsumo = import_libsumo()

                for _ in range(env.max_cycles):
                    libsumo.simulationStep()
                steps += env.max_cycles
                continue
            for _ in range(env.max_cycles):
                env.step({a: int(rng.random() < 0.1) for a in env.agents})
                steps += 1
        return steps / (time.perf_counter() - t0), steps / (time.process_time() - c0)
    finally:
        env.close()


def _ls(n, episodes, seed=0):
    ls = TrafficLocalSimulator("tls_12", n_envs=n)
    rng = np.random.default_rng(seed)
    T = ls.max_cycles
    acts = (rng.random((T, n)) < 0.1).astype(np.int64)
    infl = (rng.random((T, n, 4)) < 0.1).astype(np.int64)
    try:
        ls.reset(seed=seed)
        t0, c0 = time.perf_counter(), time.process_time()
        for ep in range(episodes):
            ls.reset(seed=seed + ep)
            for t in range(T):
                ls.step(acts[t], infl[t])
        steps = n * episodes * T
        return steps / (time.perf_counter() - t0), steps / (time.process_time() - c0)
    finally:
        ls.close()


def breakdown(sizes=(1, 8, 64), steps: int = 300, seed: int = 0, verbose: bool = True) -> dict:
    """CPU time of the parts of the LS step, per size: ``{n: {part: ms per step}}``."""
    out = {}
    keys = ("lights+add", "SUMO step", "reads", "rest", "total")
    if verbose:
        print("CPU ms per LS step (us per copy-step)")
        print(f"{'copies':>6s} " + " ".join(f"{k:>15s}" for k in keys))
    for n in sizes:
        try:
            ls = TrafficLocalSimulator("tls_12", n_envs=n, backend="inprocess")
        except SimulationBusyError as e:
            raise SystemExit(f"--breakdown needs this process's libsumo: {e}") from None
        core_parts = {"lights+add": 0.0, "SUMO step": 0.0, "reads": 0.0}
        try:
            ls.reset(seed=seed)
            core = ls._sim._core
            step, read, sim_step = core.step, core.reader.read, core._sim_step
            clock = time.process_time

            # time the core's parts by wrapping them; the core's own code runs unchanged
            def timed_read(*a, **k):
                t = clock()
                r = read(*a, **k)
                core_parts["reads"] += clock() - t
                return r

            def timed_sim_step(*a):
                t = clock()
                r = sim_step(*a)
                core_parts["SUMO step"] += clock() - t
                return r

            def timed_step(actions, inserts, *a):
                t = clock()
                r = step(actions, inserts, *a)
                core_parts["lights+add"] += clock() - t
                return r

            core.reader.read, core._sim_step, core.step = timed_read, timed_sim_step, timed_step
            rng = np.random.default_rng(seed)
            acts = (rng.random((steps, n)) < 0.1).astype(np.int64)
            infl = (rng.random((steps, n, 4)) < 0.1).astype(np.int64)
            ls.reset(seed=seed)
            for v in core_parts:
                core_parts[v] = 0.0
            t0 = clock()
            for t in range(steps):
                ls.step(acts[t], infl[t])
            total = clock() - t0
        finally:
            ls.close()
        core_total = core_parts["lights+add"]
        core_parts["lights+add"] = core_total - core_parts["SUMO step"] - core_parts["reads"]
        parts = {k: 1e3 * v / steps for k, v in core_parts.items()}
        parts["rest"] = 1e3 * (total - core_total) / steps
        parts["total"] = 1e3 * total / steps
        out[n] = parts
        if verbose:
            cells = " ".join(f"{parts[k]:8.3f} ({1e3 * parts[k] / n:4.0f})" for k in keys)
            print(f"{n:>6d} {cells}", flush=True)
    return out


def benchmark(episodes: int = 3, repeats: int = 3, verbose: bool = True) -> dict:
    """Run every measurement ``repeats`` times; return the best (wall, CPU) steps/s of each."""
    cases = {
        "raw SUMO 5x5 (in-process, incl. reset)": lambda: _gs(["tls_12"], episodes, "inprocess", raw=True),
        "GS 5x5, 1 learner, in-process": lambda: _gs(["tls_12"], episodes, "inprocess"),
        "GS 5x5, 1 learner, worker": lambda: _gs(["tls_12"], episodes, "worker"),
        "GS 5x5, 25 learners, in-process": lambda: _gs(None, episodes, "inprocess"),
        "LS n=1 (env-steps/s)": lambda: _ls(1, episodes * 4),
        "LS n=8 (env-steps/s)": lambda: _ls(8, episodes),
        "LS n=64 (env-steps/s)": lambda: _ls(64, max(1, episodes // 3)),
    }  # fmt: skip
    out = {}
    if verbose:
        print(f"{'':<42s} {'wall steps/s':>13s} {'CPU steps/s':>12s}")
    for name, fn in cases.items():
        runs = [fn() for _ in range(repeats)]
        out[name] = (max(r[0] for r in runs), max(r[1] for r in runs))
        if verbose:
            print(f"{name:<42s} {out[name][0]:>13.0f} {out[name][1]:>12.0f}", flush=True)
    return out


def configure(parser) -> None:
    """``ials-zoo sumo-bench``'s options."""
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--breakdown", action="store_true", help="split the LS step into its parts")


def run(args) -> int:
    if args.episodes < 1 or args.repeats < 1:
        raise BadInput("--episodes and --repeats must be >= 1")
    if args.breakdown:
        breakdown()
    else:
        benchmark(args.episodes, args.repeats)
    return 0
