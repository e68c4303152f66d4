"""Speed of the traffic simulators: raw SUMO, the GS and the LS (steps per second).

Usage::

    python -m ials_zoo.traffic.benchmark [--episodes 3] [--repeats 3]

Prints the best of ``repeats`` runs (the machine is shared; the best run is the least
disturbed one), as wall-clock steps/s and as steps per CPU-second of this process (less
sensitive to other load; not meaningful for the worker case, whose SUMO runs in another
process), for: raw ``simulationStep()`` of the 5 x 5 grid, the GS with one learner
(``tls_12``, the others actuated) in-process and in a worker, the GS with all 25 learners,
and the LS (``tls_12``) with 1, 8 and 64 copies (env-steps/s = copies x steps/s). Actions:
switch w.p. 0.1; LS influences: each bit 1 w.p. 0.1 (the untrained AIP).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

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
                import libsumo

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


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--episodes", type=int, default=3)
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args(argv)
    benchmark(a.episodes, a.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
