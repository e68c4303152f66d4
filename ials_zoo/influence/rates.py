"""How much influence an IALS injects: mean influence value per source and step, and the mean
observation, under a uniform random policy (what ``leaderboard/writeup.md`` quotes for the
untrained vs trained traffic AIPs); ``ials-zoo rates``."""

from __future__ import annotations

import numpy as np

from ials_zoo.errors import BadInput


def influence_rates(env_id: str, agent: str, predictor, episodes: int = 3, seed: int = 0) -> dict:
    """Mean of ``info["influence"]`` (in traffic, where each source is a 0/1 entry bit: vehicles
    entering per lane and step; in the warehouse it is a mean class index, not a rate) and
    of the observation bits over ``episodes`` IALS episodes of a uniform random policy."""
    from ials_zoo.influence.ials import make_ials  # lazy: SB3/torch

    if episodes < 1:
        raise BadInput(f"episodes must be >= 1, got {episodes}")
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
