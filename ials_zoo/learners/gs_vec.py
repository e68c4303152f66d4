"""``n_envs`` copies of a GS with every agent learning, as a multi-agent vector env (IPPO), or
of a domain's multi-agent IALS ParallelEnv (``simulator="ials"``: DIALS where the agents have
spaces of their own, every region in one simulation per copy).

Copies run in this process (``processes=0``) or spread over ``processes`` worker processes
(fresh interpreters that die with this one), which step their copies while the others do
theirs. A domain whose GS holds a process-wide resource (SUMO) puts at most one copy in this
process and the others in workers of its own lease, which step one after the other; use
``processes`` to step them at once. ``reset(seed)`` resets copy ``j`` with
``derived_seed(seed, "copy", j)``; ``reset()`` with the constructor's ``seed + j`` the first
time, and later continues each copy's own random stream.
"""

from __future__ import annotations

import numpy as np

from ials_zoo.core.domains import get_domain
from ials_zoo.core.spaces import sizes_of_env, stack_observations
from ials_zoo.core.streams import derived_seed
from ials_zoo.errors import BadInput
from ials_zoo.processes import Worker, call_all, start_all


class _Copies:
    """Some copies of the GS, stepped in turn (in this process or in a worker)."""

    def __init__(self, env_id, agents, options, seeds, simulator="gs", predictor=None):
        domain = get_domain(env_id)
        if simulator == "gs":
            self.envs = [domain.parallel_env(learners=agents, **options) for _ in seeds]
        else:
            self.envs = [domain.ials_parallel_env(agents=agents, predictor=predictor, **options) for _ in seeds]
        self.agents, self.seeds = list(agents), list(seeds)
        # agents with observations of their own lengths are zero-padded to the longest
        self.width = sizes_of_env(self.envs[0], self.agents).obs_size

    def reset(self, seeds=None):
        if seeds is not None:
            self.seeds = list(seeds)
        obs = []
        for env, seed in zip(self.envs, self.seeds):
            o, _ = env.reset(seed=seed)
            obs.append(stack_observations(o, self.agents, self.width))
        self.seeds = [None] * len(self.envs)
        return np.stack(obs, axis=1)  # [A, copies, obs]

    def step(self, actions):  # actions [A, copies]
        obs, rew, done = [], [], False
        for j, env in enumerate(self.envs):
            o, r, _, trunc, _ = env.step({a: int(actions[i, j]) for i, a in enumerate(self.agents)})
            obs.append(stack_observations(o, self.agents, self.width))
            rew.append([r[a] for a in self.agents])
            done = all(trunc.values())
        return np.stack(obs, axis=1), np.array(rew).T, done

    def set_predictors(self, predictors) -> None:
        """Every IALS copy's AIPs (an AIP set file, ...: its ``set_predictors``)."""
        for env in self.envs:
            env.set_predictors(predictors)

    def close(self):
        for env in self.envs:
            env.close()


class GSVecEnv:
    """``n_envs`` GS copies of ``agents`` (default: every agent) (module docstring);
    ``simulator="ials"``: copies of the domain's multi-agent IALS driven by ``predictor`` (an
    AIP set file or a spec)."""

    def __init__(self, env_id: str, agents=None, n_envs: int = 1, processes: int = 0, seed: int = 0,
                 simulator: str = "gs", predictor=None, **options):
        domain = get_domain(env_id)
        if simulator not in ("gs", "ials"):
            raise BadInput(f"simulator must be 'gs' or 'ials', got {simulator!r}")
        self.agents = domain.check_agents(agents, **options)
        self.n_envs, self.processes = int(n_envs), int(processes)
        if self.n_envs < 1 or self.processes < 0:
            raise BadInput("n_envs must be >= 1 and processes >= 0")
        self.observation_space, self.action_space = domain.observation_space, domain.action_space
        seeds = [seed + j for j in range(self.n_envs)]
        self._local, self._workers, self._shares = None, [], []
        if self.processes == 0:
            self._local = _Copies(env_id, self.agents, options, seeds, simulator, predictor)
            return
        shares = [[int(x) for x in s] for s in np.array_split(seeds, min(self.processes, self.n_envs)) if len(s)]
        try:
            for i, share in enumerate(shares):
                self._workers.append(Worker(_Copies, (env_id, self.agents, options, share, simulator, predictor),
                                            name=f"{simulator.upper()} worker {i}",
                                            detail=f"{len(share)} cop{'ies' if len(share) > 1 else 'y'}"))
            start_all(self._workers)
        except BaseException:
            self.close()
            raise
        self._shares = [len(share) for share in shares]

    def _bounds(self):
        ends = np.cumsum([0] + self._shares)
        return list(zip(ends[:-1], ends[1:]))

    def reset(self, seed=None):
        seeds = None if seed is None else [derived_seed(seed, "copy", j) for j in range(self.n_envs)]
        if self._local is not None:
            return self._local.reset(seeds)
        shares = [(None if seeds is None else seeds[a:b],) for a, b in self._bounds()]
        return np.concatenate(call_all(self._workers, "reset", shares), axis=1)

    def step(self, actions):
        actions = np.asarray(actions)
        if self._local is not None:
            return self._local.step(actions)
        parts = call_all(self._workers, "step", [(actions[:, a:b],) for a, b in self._bounds()])
        return (np.concatenate([p[0] for p in parts], axis=1), np.concatenate([p[1] for p in parts], axis=1),
                parts[0][2])

    def set_predictors(self, predictors) -> None:
        """Every IALS copy's AIPs (``simulator="ials"``; what the domain's IALS takes: a set file)."""
        if self._local is not None:
            self._local.set_predictors(predictors)
        else:
            call_all(self._workers, "set_predictors", [(predictors,)] * len(self._workers))

    def close(self):
        if self._local is not None:
            self._local.close()
        for w in self._workers:
            w.close()
        self._workers = []


__all__ = ["GSVecEnv"]
