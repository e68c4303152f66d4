"""Rollouts of many agents on a multi-agent vector env, for :class:`~.batched_ppo.BatchedPPO`.

A *multi-agent vector env* has ``agents``, ``n_envs`` copies, ``reset(seed=None) -> obs``
and ``step(actions) -> (obs, rewards, done)`` with arrays ``[agents, n_envs, ...]``; every
copy's episode ends (by truncation) at the same step, after which the caller resets. The
multi-agent IALS (:class:`IALSVecEnv`) and ``n_envs`` copies of the GS
(:class:`ials_zoo.learners.gs_vec.GSVecEnv`) are two.
"""

from __future__ import annotations

import numpy as np

from ials_zoo.core.streams import derived_seed
from ials_zoo.errors import BadInput
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


class SeededEpisodes:
    """The episodes a trainer runs on a multi-agent vector env, each one reproducible.

    Episode ``e`` starts from ``reset(seed=derived_seed(seed, "episode", e))`` (``seed=None``:
    unseeded), so an episode is a function of the run seed, its index and the actions taken in
    it. That makes the state small (:meth:`state`: the episode's index, its actions so far, the
    running returns) and a resume exact: :meth:`restore` resets to the same seed and replays the
    actions. Episode returns (the sum of rewards per agent and copy) are kept for the training
    log."""

    def __init__(self, env, frame_stack: int = 1, seed: int | None = None):
        self.env, self.seed = env, seed
        self.stack = FrameStack(frame_stack)
        self.running = np.zeros((len(env.agents), env.n_envs))
        self.finished: list[np.ndarray] = []  # per finished episode: returns [A] (mean over copies)
        self.steps = 0  # steps per agent and copy
        self.episode = 0
        self._start_episode()

    def _start_episode(self) -> None:
        seed = None if self.seed is None else derived_seed(self.seed, "episode", self.episode)
        self.x = self.stack.reset(self.env.reset(seed))
        self.actions: list[np.ndarray] = []  # this episode's, one [A, n] array per step
        self.running[:] = 0.0

    def _end_episode(self) -> None:
        """The running episode ended (by time limit): log its returns and start the next."""
        self.finished.append(self.running.mean(axis=1))
        self.episode += 1
        self._start_episode()

    def state(self) -> dict:
        """What :meth:`restore` needs, as plain containers (a ``weights_only`` checkpoint)."""
        return {"episode": self.episode, "actions": [a.tolist() for a in self.actions],
                "running": self.running.tolist(), "steps": self.steps}

    def restore(self, state: dict) -> None:
        """Continue where :meth:`state` was taken: the same episode, replayed to the same step.
        Only a seeded trainer can (an unseeded episode cannot be replayed)."""
        if self.seed is None:
            raise BadInput("an unseeded trainer cannot restore an episode")
        self.episode, self.steps = int(state["episode"]), int(state["steps"])
        self._start_episode()
        for a in state["actions"]:
            a = np.asarray(a, np.int64).reshape(self.running.shape)
            obs, _, done = self.env.step(a)
            if done:
                raise BadInput("the saved episode ended while it was replayed: not the run that saved it")
            self.x = self.stack.push(obs)
            self.actions.append(a)
        self.running = np.asarray(state["running"], float).reshape(self.running.shape)
        self.finished = []

    def episode_returns(self, clear: bool = True) -> np.ndarray | None:
        """Mean over the finished episodes (and copies) of each agent's return, or None."""
        if not self.finished:
            return None
        out = np.mean(self.finished, axis=0)
        if clear:
            self.finished = []
        return out


class RolloutTrainer(SeededEpisodes):
    """Trains ``learner`` on ``env``: ``n_steps`` steps of every copy, then one update, over
    reproducible episodes (:class:`SeededEpisodes`)."""

    def __init__(self, learner: BatchedPPO, env, frame_stack: int = 1, seed: int | None = None):
        if list(env.agents) != list(learner.agents) or env.n_envs != learner.cfg.n_envs:
            raise BadInput("the learner and the env must hold the same agents and copies")
        self.learner = learner
        super().__init__(env, frame_stack, seed)

    def new_episodes(self) -> None:
        """End the running episodes here and start the next ones (after the simulators
        changed, e.g. new AIPs: an episode then runs on one simulator throughout). The last
        rollout bootstrapped from this state's value, as at a time limit; the cut episodes'
        returns are not logged."""
        self.episode += 1
        self.learner.reward_scale.returns[:] = 0.0
        self._start_episode()

    def collect_and_update(self) -> dict:
        """One rollout of ``n_steps`` and one PPO update; returns the update's statistics."""
        cfg, learner = self.learner.cfg, self.learner
        T = cfg.n_steps
        xs, acts, logps, vals, rews, dones = [], [], [], [], [], []
        for _ in range(T):
            a, v, lp = learner.act(self.x)
            obs, r, done = self.env.step(a)
            self.actions.append(np.asarray(a, np.int64))
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
                self._end_episode()
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


__all__ = ["FrameStack", "IALSVecEnv", "RolloutTrainer", "SeededEpisodes"]
