"""Everything a stable-baselines3 PPO run's future depends on, as a checkpoint of tensors and
plain containers (read back with ``torch.load(weights_only=True)``), so that a resumed run
ends bitwise equal to the run that was never stopped.

What it holds, and why each part is needed:

* the policy's weights and the optimiser's state (Adam's moments);
* the step and update counters (the learning-rate schedule reads the steps);
* the reward scale (``VecNormalize``'s running variance of the discounted return);
* the episodes of SB3's episode-statistics buffer (what ``progress.csv`` reports);
* the random streams SB3 draws from: torch's global generator (actions), numpy's global one
  (minibatch order) and Python's.

The environments' state is the one part that cannot be saved (a SUMO simulation mid-episode).
Instead, every checkpoint starts new episodes, seeded by the run's seed and its step count
(:func:`restart_episodes`), and a resumed run starts the very same ones. The episodes cut at a
checkpoint are bootstrapped as any rollout's last step is (SB3 adds ``gamma * V(s)`` at the
rollout's end), so nothing is learned wrong; checkpoints come every evaluation (100k steps by
default), so few episodes are cut.
"""

from __future__ import annotations

import random
from collections import deque

import numpy as np
import torch
from stable_baselines3.common.vec_env import VecNormalize


def reward_scale_of(venv):
    """The ``VecNormalize`` inside a chain of SB3 vec-env wrappers, or None."""

    while venv is not None:
        if isinstance(venv, VecNormalize):
            return venv
        venv = getattr(venv, "venv", None)
    return None


def episode_seed(seed: int, steps: int) -> int:
    """The seed of the episodes a checkpoint at ``steps`` starts (the same in a resumed run)."""
    return int(np.random.SeedSequence([int(seed), int(steps)]).generate_state(1)[0]) % (2**31 - 1)


def restart_episodes(model, seed: int) -> None:
    """Start new episodes in every environment of ``model``, seeded by ``seed`` (copy ``i``:
    ``seed + i``). Every wrapper resets too: frame stacks, episode statistics, the reward
    scale's running return."""
    env = model.get_env()
    env.seed(int(seed))
    model._last_obs = env.reset()
    model._last_episode_starts = np.ones((env.num_envs,), dtype=bool)
    scale = reward_scale_of(env)
    if scale is not None:
        model._last_original_obs = scale.get_original_obs()


def random_streams() -> dict:
    """The global random streams SB3 draws from, as tensors and plain containers."""
    kind, keys, pos, has_gauss, cached = np.random.get_state()
    version, internal, gauss_next = random.getstate()
    return {"torch": torch.get_rng_state(),
            "numpy": {"kind": kind, "keys": torch.from_numpy(keys.astype(np.int64)), "pos": int(pos),
                      "has_gauss": int(has_gauss), "cached": float(cached)},
            "python": {"version": version, "internal": list(internal), "gauss_next": gauss_next}}


def set_random_streams(state: dict) -> None:
    torch.set_rng_state(state["torch"])
    n = state["numpy"]
    np.random.set_state((n["kind"], n["keys"].numpy().astype(np.uint32), n["pos"], n["has_gauss"], n["cached"]))
    p = state["python"]
    random.setstate((p["version"], tuple(p["internal"]), p["gauss_next"]))


def model_state(model) -> dict:
    """``model``'s learning state (see the module docstring; not the environments')."""
    state = {"policy": model.policy.state_dict(), "optimizer": model.policy.optimizer.state_dict(),
             "num_timesteps": int(model.num_timesteps), "n_updates": int(model._n_updates),
             "episodes": _columns(model.ep_info_buffer or [])}
    scale = reward_scale_of(model.get_env())
    if scale is not None:
        # float64 throughout: a float32 count alone shifts the weights by an ulp after a resume
        state["reward_rms"] = {k: torch.tensor(np.asarray(getattr(scale.ret_rms, k)), dtype=torch.float64)
                               for k in ("mean", "var", "count")}
    return state


def _columns(episodes) -> dict:
    """SB3's episode records as tensors, one per key, in their own dtypes (a float32 return
    averaged as a float64 one reads differently in the last digits)."""
    episodes = list(episodes)
    return {k: torch.from_numpy(np.asarray([e[k] for e in episodes])) for k in (episodes[0] if episodes else {})}


def _rows(columns: dict) -> list[dict]:
    arrays = {k: v.numpy() for k, v in columns.items()}
    n = len(next(iter(arrays.values()))) if arrays else 0
    return [{k: a[i] for k, a in arrays.items()} for i in range(n)]


def load_model_state(model, state: dict) -> None:
    """Put :func:`model_state`'s ``state`` back into ``model`` (built with the same settings)."""

    model.policy.load_state_dict(state["policy"])
    model.policy.optimizer.load_state_dict(state["optimizer"])
    model.num_timesteps = int(state["num_timesteps"])
    model._n_updates = int(state.get("n_updates", 0))
    model.ep_info_buffer = deque(_rows(state.get("episodes", {})), maxlen=model._stats_window_size)
    model.ep_success_buffer = deque(maxlen=model._stats_window_size)
    scale = reward_scale_of(model.get_env())
    if scale is not None and "reward_rms" in state:
        rms = state["reward_rms"]
        scale.ret_rms.mean, scale.ret_rms.var = rms["mean"].numpy(), rms["var"].numpy()
        scale.ret_rms.count = float(rms["count"].item())


def checkpoint_models(models: dict, seeds: dict, steps: int) -> dict:
    """The exact checkpoint of SB3 models that share this process's random streams, at
    ``steps``: each model starts new episodes (seeded by ``seeds[key]`` and ``steps``), then
    their states and the streams are taken, in that order (:func:`resume_models` repeats it)."""
    for key, model in models.items():
        restart_episodes(model, episode_seed(seeds[key], steps))
    return {"models": {key: model_state(model) for key, model in models.items()}, "streams": random_streams()}


def resume_models(models: dict, seeds: dict, steps: int, state: dict) -> None:
    """Put :func:`checkpoint_models`' ``state`` back into freshly built ``models``: their
    learning state, the same new episodes, then the random streams (last: building and resetting
    may draw from them)."""
    for key, model in models.items():
        load_model_state(model, state["models"][key])
        restart_episodes(model, episode_seed(seeds[key], steps))
    set_random_streams(state["streams"])


__all__ = ["checkpoint_models", "episode_seed", "load_model_state", "model_state", "random_streams", "restart_episodes",
           "resume_models", "reward_scale_of", "set_random_streams"]
