"""How fast ``ppo_single`` trains on each simulator, and how fast it could at best.

:func:`ppo_throughput` times ``model.learn`` of the baseline's own PPO (same settings, same
vec envs and wrappers as :mod:`ials_zoo.baselines.ppo_single`) on a training simulator, and on
``"none"``: a vec env of the same spaces whose step costs nothing (:class:`FreeVecEnv`). The
latter is PPO's own cost (policy forward passes, rollout buffer, updates), which bounds what
any faster simulator can save: with PPO alone taking ``t_ppo`` per step and the GS ``t_gs``,
no IALS can train in less than ``t_ppo / (t_ppo + t_gs)`` of the GS's wall-clock.

Used by ``ials-zoo bench --ppo``.
"""

from __future__ import annotations

import time

import numpy as np
import torch
from stable_baselines3.common.vec_env import VecEnv, VecFrameStack, VecMonitor

from ials_zoo.baselines.arguments import hidden_sizes
from ials_zoo.baselines.ppo_single import Args, TrainingSimulator, make_training_env, update_size
from ials_zoo.baselines.sb3_run import as_float_box, make_ppo
from ials_zoo.core.domains import get_domain
from ials_zoo.errors import BadInput

NO_SIMULATOR = "none"


class FreeVecEnv(VecEnv):
    """A ``VecEnv`` with given spaces whose steps cost nothing: zero observations and rewards,
    every episode truncated after ``episode_length`` steps (as the zoo's episodes are)."""

    def __init__(self, num_envs: int, observation_space, action_space, episode_length: int):
        self.render_mode = None
        super().__init__(num_envs, observation_space, action_space)
        self.episode_length = int(episode_length)
        self._t = 0
        self._obs = np.zeros((num_envs, *observation_space.shape), dtype=observation_space.dtype)

    def reset(self):
        self._t = 0
        return self._obs.copy()

    def step_async(self, actions):
        pass

    def step_wait(self):
        self._t += 1
        done = self._t >= self.episode_length
        infos = [{} for _ in range(self.num_envs)]
        if done:
            self._t = 0
            for info in infos:
                info["TimeLimit.truncated"] = True
                info["terminal_observation"] = self._obs[0].copy()
        return self._obs.copy(), np.zeros(self.num_envs, dtype=np.float32), np.full(self.num_envs, done), infos

    def close(self):
        pass

    def get_attr(self, attr_name, indices=None):
        return [getattr(self, attr_name)] * self.num_envs

    def set_attr(self, attr_name, value, indices=None):
        setattr(self, attr_name, value)

    def env_method(self, method_name, *method_args, indices=None, **method_kwargs):
        return [None] * self.num_envs

    def env_is_wrapped(self, wrapper_class, indices=None):
        return [False] * self.num_envs


def ppo_throughput(env_id: str, agent: str, simulator: str, steps: int = 30_000, n_envs: int = 8,
                   seed: int = 0) -> dict:
    """PPO environment steps per second of ``ppo_single`` on ``simulator`` (``gs``, ``ials``,
    any ``--simulator`` value, or ``"none"`` for :class:`FreeVecEnv`), over ``steps`` steps.

    Construction is not timed; the measurement includes rollouts and updates, as a training
    run's wall-clock does (but no GS evaluations)."""

    if steps < 1 or n_envs < 1:
        raise BadInput(f"steps and n_envs must be >= 1, got {steps} and {n_envs}")
    torch.set_num_threads(1)
    dom = get_domain(env_id)
    agent = dom.check_agent(agent)
    args = Args(env_id=env_id, agent=agent, simulator="ials" if simulator == NO_SIMULATOR else simulator,
                n_envs=n_envs, seed=seed)
    args.n_steps, args.batch_size = update_size(args, dom)
    venv, _ = make_training_env(TrainingSimulator.of(args, dom, agent, {}), n_envs, seed)
    try:
        if simulator == NO_SIMULATOR:
            boxed = as_float_box(venv)
            free = FreeVecEnv(n_envs, boxed.observation_space, boxed.action_space, dom.episode_length)
            venv.close()
            venv = free
        venv = VecMonitor(as_float_box(venv))
        if dom.frame_stack > 1:
            venv = VecFrameStack(venv, dom.frame_stack)
        model = make_ppo(venv, args, hidden_sizes(args.net_arch))
        start = time.perf_counter()
        model.learn(steps)
        seconds = time.perf_counter() - start
    finally:
        venv.close()
    done = int(model.num_timesteps)
    return {"domain": env_id, "agent": agent, "simulator": simulator, "n_envs": n_envs, "steps": done,
            "seconds": seconds, "steps_per_s": done / seconds}


def ppo_bound(rows: list[dict]) -> dict:
    """From :func:`ppo_throughput` rows of one domain (``gs``, ``none`` and others): per
    simulator, its wall-clock per step relative to the GS, and the floor set by PPO alone."""
    by = {r["simulator"]: r for r in rows}
    if "gs" not in by or NO_SIMULATOR not in by:
        raise BadInput("ppo_bound needs a 'gs' row and a 'none' row")
    t_gs = 1.0 / by["gs"]["steps_per_s"]
    out = {name: (1.0 / r["steps_per_s"]) / t_gs for name, r in by.items()}
    return {"time_per_step_vs_gs": out, "floor": out[NO_SIMULATOR]}
