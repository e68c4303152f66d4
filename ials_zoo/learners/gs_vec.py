"""``n_envs`` copies of a GS with every agent learning, as a multi-agent vector env (IPPO), or
of a domain's multi-agent IALS ParallelEnv (``simulator="ials"``: DIALS where the agents have
spaces of their own, every region in one simulation per copy; or, where the domain batches
its IALS copies, ``Domain.ials_batched_env``, all copies as one batch).

Copies run in this process (``processes=0``) or spread over ``processes`` worker processes
(fresh interpreters that die with this one), or Ray actors (``copies_on="ray"``, on a local Ray
of their own or the cluster at ``ray_address``: :class:`~ials_zoo.runtime.ray_actors.RayActors`), which
step their copies while the others do theirs. A domain whose GS holds a process-wide resource (SUMO) puts at most one copy in this
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
from ials_zoo.runtime.processes import Worker, call_all, start_all
from ials_zoo.runtime.ray_actors import RayActors, where


class _Copies:
    """Some copies of the GS, stepped in turn (in this process or in a worker)."""

    def __init__(self, env_id, agents, options, seeds, simulator="gs", predictor=None):
        domain = get_domain(env_id)
        self.batched = None  # a domain's IALS copies stepped as one batch (its ials_batched_env)
        if simulator != "gs" and domain.ials_batched_env is not None:
            self.batched = domain.ials_batched_env(agents, predictor, seeds, **options)
        if self.batched is not None:
            self.envs, self.agents, self.seeds, self.width = [], list(agents), list(seeds), self.batched.width
            return
        if simulator == "gs":
            self.envs = [domain.parallel_env(learners=agents, **options) for _ in seeds]
        else:
            self.envs = [domain.ials_parallel_env(agents=agents, predictor=predictor, **options) for _ in seeds]
        self.agents, self.seeds = list(agents), list(seeds)
        # agents with observations of their own lengths are zero-padded to the longest
        self.width = sizes_of_env(self.envs[0], self.agents).obs_size

    def reset(self, seeds=None):
        if self.batched is not None:
            return self.batched.reset(seeds)
        if seeds is not None:
            self.seeds = list(seeds)
        obs = []
        for env, seed in zip(self.envs, self.seeds):
            o, _ = env.reset(seed=seed)
            obs.append(stack_observations(o, self.agents, self.width))
        self.seeds = [None] * len(self.envs)
        return np.stack(obs, axis=1)  # [A, copies, obs]

    def step(self, actions):  # actions [A, copies]
        if self.batched is not None:
            return self.batched.step(actions)
        obs, rew, done = [], [], False
        for j, env in enumerate(self.envs):
            o, r, _, trunc, _ = env.step({a: int(actions[i, j]) for i, a in enumerate(self.agents)})
            obs.append(stack_observations(o, self.agents, self.width))
            rew.append([r[a] for a in self.agents])
            done = all(trunc.values())
        return np.stack(obs, axis=1), np.array(rew).T, done

    def set_predictors(self, predictors) -> None:
        """Every IALS copy's AIPs (an AIP set file, ...: its ``set_predictors``)."""
        if self.batched is not None:
            self.batched.set_predictors(predictors)
        for env in self.envs:
            env.set_predictors(predictors)

    def close(self):
        if self.batched is not None:
            self.batched.close()
        for env in self.envs:
            env.close()

    def where(self) -> tuple[int, str]:
        return where()


class _ProcessWorkers:
    """The shares of copies in worker processes (module docstring)."""

    def __init__(self, arguments: list[tuple], simulator: str):
        self.workers = []
        try:
            for i, args in enumerate(arguments):
                n = len(args[3])
                self.workers.append(Worker(_Copies, args, name=f"{simulator.upper()} worker {i}",
                                           detail=f"{n} cop{'ies' if n > 1 else 'y'}"))
            start_all(self.workers)
        except BaseException:
            self.close()
            raise

    def call(self, method: str, args: list | None = None) -> list:
        return call_all(self.workers, method, args)

    def close(self):
        for w in self.workers:
            w.close()
        self.workers = []


class GSVecEnv:
    """``n_envs`` GS copies of ``agents`` (default: every agent) (module docstring);
    ``simulator="ials"``: copies of the domain's multi-agent IALS driven by ``predictor`` (an
    AIP set file or a spec)."""

    def __init__(self, env_id: str, agents=None, n_envs: int = 1, processes: int = 0, seed: int = 0,
                 simulator: str = "gs", predictor=None, copies_on: str = "process", ray_address: str | None = None,
                 **options):
        domain = get_domain(env_id)
        if simulator not in ("gs", "ials"):
            raise BadInput(f"simulator must be 'gs' or 'ials', got {simulator!r}")
        if copies_on not in ("process", "ray"):
            raise BadInput(f"copies_on must be 'process' or 'ray', got {copies_on!r}")
        self.agents = domain.check_agents(agents, **options)
        self.n_envs, self.processes = int(n_envs), int(processes)
        if self.n_envs < 1 or self.processes < 0:
            raise BadInput("n_envs must be >= 1 and processes >= 0")
        if copies_on == "ray" and self.processes == 0:
            raise BadInput("copies_on='ray' needs processes >= 1 (the number of Ray actors)")
        self.observation_space, self.action_space = domain.observation_space, domain.action_space
        seeds = [seed + j for j in range(self.n_envs)]
        self._local, self._workers, self._shares = None, None, []
        if self.processes == 0:
            self._local = _Copies(env_id, self.agents, options, seeds, simulator, predictor)
            return
        shares = [[int(x) for x in s] for s in np.array_split(seeds, min(self.processes, self.n_envs)) if len(s)]
        arguments = [(env_id, self.agents, options, share, simulator, predictor) for share in shares]
        if copies_on == "ray":
            self._workers = RayActors(_Copies, arguments, ray_address, what=f"{simulator.upper()} Ray actor")
        else:
            self._workers = _ProcessWorkers(arguments, simulator)
        self._shares = [len(share) for share in shares]

    def _bounds(self):
        ends = np.cumsum([0] + self._shares)
        return list(zip(ends[:-1], ends[1:]))

    def reset(self, seed=None):
        seeds = None if seed is None else [derived_seed(seed, "copy", j) for j in range(self.n_envs)]
        if self._local is not None:
            return self._local.reset(seeds)
        shares = [(None if seeds is None else seeds[a:b],) for a, b in self._bounds()]
        return np.concatenate(self._workers.call("reset", shares), axis=1)

    def step(self, actions):
        actions = np.asarray(actions)
        if self._local is not None:
            return self._local.step(actions)
        parts = self._workers.call("step", [(actions[:, a:b],) for a, b in self._bounds()])
        return (np.concatenate([p[0] for p in parts], axis=1), np.concatenate([p[1] for p in parts], axis=1),
                parts[0][2])

    def set_predictors(self, predictors) -> None:
        """Every IALS copy's AIPs (``simulator="ials"``; what the domain's IALS takes: a set file)."""
        if self._local is not None:
            self._local.set_predictors(predictors)
        else:
            self._workers.call("set_predictors", [(predictors,)] * len(self._shares))

    def close(self):
        if self._local is not None:
            self._local.close()
        if self._workers is not None:
            self._workers.close()
            self._workers = None


__all__ = ["GSVecEnv"]
