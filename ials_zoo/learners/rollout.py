"""Rollouts of many agents on a multi-agent vector env, for :class:`~.batched_ppo.BatchedPPO`.

A *multi-agent vector env* has ``agents``, ``n_envs`` copies, ``reset(seed=None) -> obs``
and ``step(actions) -> (obs, rewards, done)`` with arrays ``[agents, n_envs, ...]``; every
copy's episode ends (by truncation) at the same step, after which the caller resets. The
multi-agent IALS (:class:`IALSVecEnv`) and ``n_envs`` copies of the GS
(:class:`ials_zoo.learners.gs_vec.GSVecEnv`) are two.
"""

from __future__ import annotations

import numpy as np

from ials_zoo.learners.batched_ppo import BatchedPPO, gae


class IALSVecEnv:
    """:class:`ials_zoo.influence.multi.MultiAgentIALS` as a multi-agent vector env."""

    def __init__(self, core):
        self.core = core
        self.agents, self.n_envs = list(core.agents), core.n_envs
        self.observation_space, self.action_space = core.ls.observation_space, core.ls.action_space

    def reset(self, seed=None):
        return self.core.reset(seed)[0]

    def step(self, actions):
        obs, rewards, _, _, done = self.core.step(actions)
        return obs, rewards, done

    def set_predictors(self, predictors: dict) -> None:
        self.core.set_predictors(predictors)

    def close(self):
        self.core.close()


class FrameStack:
    """The last ``k`` observations of every (agent, copy), newest last, zeros before an
    episode's first (SB3's ``VecFrameStack``)."""

    def __init__(self, k: int):
        self.k = int(k)
        self.buf = None

    def reset(self, obs):
        obs = np.asarray(obs, np.float32)
        if self.k == 1:
            self.buf = obs
            return obs
        w = obs.shape[-1]
        self.buf = np.zeros(obs.shape[:-1] + (w * self.k,), np.float32)
        self.buf[..., -w:] = obs
        return self.buf

    def push(self, obs):
        obs = np.asarray(obs, np.float32)
        if self.k == 1:
            self.buf = obs
            return obs
        w = obs.shape[-1]
        buf = np.empty_like(self.buf)
        buf[..., :-w] = self.buf[..., w:]
        buf[..., -w:] = obs
        self.buf = buf
        return buf


class RolloutTrainer:
    """Trains ``learner`` on ``env``: ``n_steps`` steps of every copy, then one update.

    Episode returns (the sum of rewards per agent and copy) are kept for the training log.
    The env is reset by the trainer (its first reset uses ``seed``)."""

    def __init__(self, learner: BatchedPPO, env, frame_stack: int = 1, seed: int | None = None):
        if list(env.agents) != list(learner.agents) or env.n_envs != learner.cfg.n_envs:
            raise ValueError("the learner and the env must hold the same agents and copies")
        self.learner, self.env = learner, env
        self.stack = FrameStack(frame_stack)
        self.x = self.stack.reset(env.reset(seed))
        A, n = len(env.agents), env.n_envs
        self.running = np.zeros((A, n))
        self.finished: list[np.ndarray] = []  # per finished episode: returns [A] (mean over copies)
        self.steps = 0  # steps per agent and copy

    def collect_and_update(self) -> dict:
        """One rollout of ``n_steps`` and one PPO update; returns the update's statistics."""
        cfg, learner = self.learner.cfg, self.learner
        T = cfg.n_steps
        xs, acts, logps, vals, rews, dones = [], [], [], [], [], []
        for _ in range(T):
            a, v, lp = learner.act(self.x)
            obs, r, done = self.env.step(a)
            r = np.asarray(r, np.float64)
            self.running += r
            if cfg.normalize_reward:
                r = learner.reward_scale(r, done)
            xs.append(self.x)
            acts.append(a)
            logps.append(lp)
            vals.append(v)
            if done:
                # time limit: bootstrap the value of the last state (SB3's TimeLimit handling)
                terminal = self.stack.push(obs)
                r = r + cfg.gamma * learner.values(terminal)
                self.finished.append(self.running.mean(axis=1))
                self.running[:] = 0.0
                self.x = self.stack.reset(self.env.reset())
            else:
                self.x = self.stack.push(obs)
            rews.append(r)
            dones.append(np.full(r.shape, float(done)))
        self.steps += T
        last = learner.values(self.x)
        adv, ret = gae(np.stack(rews), np.stack(vals), np.stack(dones), last, cfg.gamma, cfg.gae_lambda)

        def flat(x):  # [T, A, n, ...] -> [A, T * n, ...]
            x = np.stack(x) if isinstance(x, list) else x
            return np.swapaxes(x, 0, 1).reshape(x.shape[1], x.shape[0] * x.shape[2], *x.shape[3:])

        stats = learner.update(flat(xs), flat(acts), flat(logps), flat(ret), flat(adv), flat(vals))
        return stats

    def episode_returns(self, clear: bool = True) -> np.ndarray | None:
        """Mean over the finished episodes (and copies) of each agent's return, or None."""
        if not self.finished:
            return None
        out = np.mean(self.finished, axis=0)
        if clear:
            self.finished = []
        return out


__all__ = ["FrameStack", "IALSVecEnv", "RolloutTrainer"]
