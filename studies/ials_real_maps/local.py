"""What a local simulator of every light's region costs against the GS, per agent-step, on a
RESCO map: ``sumo_net_v0`` (the GS) and :class:`ials_zoo.sumo_net.local.LocalNetEnv` (every
region side by side in one SUMO simulation, influence drawn from a recorded GS hour), both
ParallelEnvs with every light acting at random, both in a worker process (one pipe round trip
per decision each). Episodes alternate, so machine load falls on both; the ratio is taken per
pair of episodes of the same seed. Also each side's mean reward and queue under that random
policy (the influence drawn from GS statistics, not an AIP: how far they agree is a first look
at fidelity, not a result).

``--aips FILE`` (an AIP set: ``ials-zoo train-aip --agent all`` or ``studies/ials_real_maps/island.py``)
measures the multi-agent IALS instead (:class:`ials_zoo.sumo_net.ials_env.IALSNetEnv`: the same
regions, each fed by its trained AIP), AIP sampling included.

Usage: python studies/ials_real_maps/local.py [--net ingolstadt21] [--repeats 3] [--max-cycles N] [--aips FILE]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from ials_zoo.sumo_net.env import SumoNetEnv
from ials_zoo.sumo_net.ials_env import IALSNetEnv
from ials_zoo.sumo_net.local import LocalNetEnv


def episode(env, seed: int, rng) -> tuple[float, float, float]:
    """``(seconds per decision, mean reward over lights and decisions, mean queue)``."""
    draws = {a: rng.integers(env.action_space(a).n, size=env.scenario.decisions).tolist() for a in env.possible_agents}
    start, n, rewards = time.perf_counter(), 0, []
    env.reset(seed=seed)
    while env.agents:
        _, r, *_ = env.step({a: draws[a][n] for a in env.agents})
        rewards.append(np.mean(list(r.values())))
        n += 1
    return (time.perf_counter() - start) / n, float(np.mean(rewards)), env.episode_metrics()["queue"]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--net", default="ingolstadt21")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--max-cycles", type=int, default=None)
    parser.add_argument("--aips", default=None, help="an AIP set file: measure the multi-agent IALS")
    args = parser.parse_args(argv)
    options = {"net": args.net, "backend": "worker", "fresh_process": False, "max_cycles": args.max_cycles}
    start = time.perf_counter()
    local = IALSNetEnv(predictors=args.aips, **options) if args.aips else LocalNetEnv(**options)
    built = time.perf_counter() - start
    gs = SumoNetEnv(**options)
    rows = []
    try:
        for seed in range(args.repeats):
            g = episode(gs, seed, np.random.default_rng(seed))
            x = episode(local, seed, np.random.default_rng(seed))
            rows.append((g, x))
            print(f"seed {seed}: GS {g[0] * 1e3:.1f} ms per decision, local {x[0] * 1e3:.1f} ({x[0] / g[0]:.2f}); "
                  f"reward GS {g[1]:.3f} local {x[1]:.3f}; queue GS {g[2]:.2f} local {x[2]:.2f}", flush=True)
    finally:
        local.close()
        gs.close()
    ratios = [x[0] / g[0] for g, x in rows]
    n = len(gs.possible_agents)
    print(f"{args.net}: {n} lights, {len(local.regions)} regions, built in {built:.0f} s (cut, merge, GS recording); "
          f"local / GS per agent-step {np.median(ratios):.2f} [{min(ratios):.2f}, {max(ratios):.2f}] over "
          f"{len(rows)} episode pairs; GS {np.median([g[0] for g, _ in rows]) / n * 1e6:,.0f} µs per agent-step")


if __name__ == "__main__":
    main()
