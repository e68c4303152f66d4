"""How much influence an IALS injects: mean influence value per source and step, and the mean
observation, under a uniform random policy (what ``leaderboard/writeup.md`` quotes for the
untrained vs trained traffic AIPs).

    python -m ials_zoo.influence.rates --env traffic_grid_v0 --agent tls_12 \\
        --predictors untrained,fixed:0.1,trained --episodes 3
"""

from __future__ import annotations

import argparse

import numpy as np


def influence_rates(env_id: str, agent: str, predictor, episodes: int = 3, seed: int = 0) -> dict:
    """Mean of ``info["influence"]`` (in traffic, where each source is a 0/1 entry bit: vehicles
    entering per lane and step; in the warehouse it is a mean class index, not a rate) and
    of the observation bits over ``episodes`` IALS episodes of a uniform random policy."""
    from ials_zoo.influence.ials import make_ials

    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    env = make_ials(env_id, agent, predictor=predictor, seed=seed)
    env.action_space.seed(seed)
    influence, obs_mean = [], []
    try:
        for ep in range(episodes):
            env.reset(seed=seed + ep)
            truncated = False
            while not truncated:
                obs, _, _, truncated, info = env.step(env.action_space.sample())
                influence.append(np.mean(info["influence"]))
                obs_mean.append(np.mean(obs))
    finally:
        env.close()
    return {"predictor": str(predictor), "influence_mean": float(np.mean(influence)),
            "observation_mean": float(np.mean(obs_mean)), "steps": len(influence)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="traffic_grid_v0")
    parser.add_argument("--agent", default="tls_12")
    parser.add_argument("--predictors", default="untrained,fixed:0.1,trained")
    parser.add_argument("--episodes", type=int, default=3)
    args = parser.parse_args(argv)
    for pred in [p.strip() for p in args.predictors.split(",") if p.strip()]:
        r = influence_rates(args.env, args.agent, pred, args.episodes)
        print(f"{pred:<24} influence per source and step {r['influence_mean']:.3f}   "
              f"observation mean {r['observation_mean']:.3f}   ({r['steps']} steps)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
