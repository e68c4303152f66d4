"""What untrained-DIALS would train on: the multi-agent IALS with untrained AIPs against trained ones.

Usage: python studies/ials_real_maps/untrained_ials.py --net cologne8 --aips runs/dials_exits2/cologne8_s0/aips.pt
       [--decisions 60] [--repeats 2]

Every light acts at random for ``--decisions`` decisions in each IALS, alternating (the same seed per
pair), and the script prints the wall-clock per decision and the mean queue per light. An untrained AIP
draws about uniformly over 0, 1 and 2+ vehicles per second at every entry point and blocks half the exits,
so it floods the regions; docs/sumo_net.md ("DIALS over seeds and maps") reports what that costs.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import ials_zoo


def run(predictor: str, net: str, decisions: int, seed: int) -> tuple[float, float]:
    """Seconds per decision and the mean queue per light of one stretch with random lights."""
    env = ials_zoo.make_ials_parallel_env("sumo_net_v0", predictor=predictor, net=net, max_cycles=decisions)
    try:
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        start, n = time.perf_counter(), 0
        while env.agents:
            env.step({a: int(rng.integers(env.action_space(a).n)) for a in env.agents})
            n += 1
        return (time.perf_counter() - start) / n, env.episode_metrics()["queue"]
    finally:
        env.close()


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--net", default="cologne8")
    parser.add_argument("--aips", required=True, help="a trained AIP set (e.g. a DIALS run's aips.pt)")
    parser.add_argument("--decisions", type=int, default=60)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args(argv)
    for seed in range(args.repeats):
        for name, predictor in (("untrained", "untrained"), ("trained", args.aips)):
            seconds, queue = run(predictor, args.net, args.decisions, seed)
            print(f"{name} AIPs, seed {seed}: {seconds * 1e3:.1f} ms per decision, mean queue {queue:.1f}", flush=True)


if __name__ == "__main__":
    main()
