"""Where the multi-agent IALS of a RESCO map spends its time: cProfile over decisions of
:class:`ials_zoo.sumo_net.ials_env.IALSNetEnv` in this process (``backend="inprocess"``), every
light at random, every AIP the GS's recorded entry frequencies
(:func:`ials_zoo.sumo_net.island.gs_marginal_predictors`). Prints the functions by own time.

Usage: python studies/ials_real_maps/ials_profile.py [--net ingolstadt21] [--decisions 150]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time

import numpy as np


def main(argv=None) -> None:
    from ials_zoo import sumo_net_v0
    from ials_zoo.sumo_net.ials_env import IALSNetEnv
    from ials_zoo.sumo_net.island import gs_marginal_predictors

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--net", default="ingolstadt21")
    parser.add_argument("--decisions", type=int, default=150)
    args = parser.parse_args(argv)
    gs = sumo_net_v0.parallel_env(net=args.net)
    agents = list(gs.possible_agents)
    gs.close()
    env = IALSNetEnv(predictors=gs_marginal_predictors(agents, net=args.net), net=args.net, backend="inprocess")
    rng = np.random.default_rng(0)
    try:
        env.reset(seed=1)
        draws = [{a: int(rng.integers(env.action_space(a).n)) for a in agents} for _ in range(args.decisions)]
        profile = cProfile.Profile()
        start = time.perf_counter()
        profile.enable()
        for actions in draws:
            env.step(actions)
        profile.disable()
        seconds = time.perf_counter() - start
    finally:
        env.close()
    print(f"{args.net}: {args.decisions / seconds:.1f} decisions/s under the profiler, "
          f"{seconds / (args.decisions * len(agents)) * 1e6:,.0f} µs per agent-decision")
    pstats.Stats(profile).sort_stats("tottime").print_stats(12)


if __name__ == "__main__":
    main()
