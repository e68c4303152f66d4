"""The global simulator as seen by one learning agent: a Gymnasium ``Env``.

Every other agent of the GS is driven by its scripted controller, which is the evaluation
protocol of the paper (SPEC §3: "a policy trained anywhere is scored on the GS, with the other
agents scripted") and the "GS" training simulator of the baselines.

Episodes of the zoo end by **truncation** after ``episode_length`` steps: ``step`` returns
``terminated=False, truncated=True`` at the end, so that SB3's ``DummyVecEnv`` /
``SubprocVecEnv`` mark the step ``TimeLimit.truncated`` and PPO bootstraps the value of the
last observation instead of treating it as terminal.

Observations are exposed as a ``Box`` of ``float32`` (a ``MultiBinary`` GS observation becomes
``Box(0, 1)``): SB3's frame stacking (``VecFrameStack``) needs a ``Box``, and the IALS exposes
the same space, so a policy trained on either runs on the other.

libsumo holds one simulation per process: for the traffic GS, vectorised training must put each
``SingleAgentGS`` in its own process (:func:`make_gs_vec_env` does that by default for domains
marked ``Domain.one_simulation_per_process``).
"""

from __future__ import annotations

import functools
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from ials_zoo.core.domains import get_domain


def needs_own_process(env_id: str) -> bool:
    """True when each GS of ``env_id`` must live in its own process (SUMO via libsumo):
    ``Domain.one_simulation_per_process``."""
    return get_domain(env_id).one_simulation_per_process


def box_space(space: spaces.Space) -> spaces.Box:
    """The float32 ``Box`` the baselines see for a GS/LS observation space."""
    if isinstance(space, spaces.MultiBinary):
        return spaces.Box(0.0, 1.0, shape=tuple(np.atleast_1d(space.n)), dtype=np.float32)
    if isinstance(space, spaces.Box):
        return spaces.Box(
            space.low.astype(np.float32), space.high.astype(np.float32), dtype=np.float32
        )
    raise TypeError(
        f"observation space {space!r} is not supported by the baselines; expected a Box or "
        "MultiBinary"
    )


def check_agent(env_id: str, agent: str, **options) -> str:
    """Raise a ValueError naming the domain's agents when ``agent`` is not one of them
    (:meth:`ials_zoo.core.Domain.check_agent`)."""
    return get_domain(env_id).check_agent(agent, **options)


class SingleAgentGS(gymnasium.Env):
    """The GS of ``env_id`` from the point of view of ``agent``; every other agent is scripted.

    Args:
        env_id: versioned domain id (``"warehouse_v0"``, ``"traffic_grid_v0"``).
        agent: the learning agent (e.g. ``"robot_20"``, ``"tls_12"``).
        scripted_learner: drive ``agent`` by its scripted controller too (actions passed to
            ``step`` are ignored); used to score the domain's scripted reference policy.
        **options: passed to the domain's ``parallel_env``.

    Observation: the agent's GS observation as ``float32`` (see module doc). Action: the
    agent's GS action space. Reward: the agent's GS reward. Episode end: truncation after the
    domain's episode length (``terminated`` is always False).
    """

    metadata = {"render_modes": []}

    def __init__(self, env_id: str, agent: str, scripted_learner: bool = False, **options):
        self.env_id = env_id
        self.agent = check_agent(env_id, agent, **options)
        self.scripted_learner = bool(scripted_learner)
        self.options = dict(options)
        dom = get_domain(env_id)
        self._par = dom.parallel_env(
            learners=[agent], scripted_learners=self.scripted_learner, **options
        )
        self.observation_space = box_space(self._par.observation_space(agent))
        self.action_space = self._par.action_space(agent)
        self._done = True

    @property
    def parallel(self):
        """The GS this env drives (a PettingZoo ``ParallelEnv`` of every agent)."""
        return self._par

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        obs, infos = self._par.reset(seed=seed, options=options)
        self._done = False
        return np.asarray(obs[self.agent], dtype=np.float32), dict(infos.get(self.agent, {}))

    def step(self, action: Any):
        if self._done:
            raise RuntimeError("SingleAgentGS.step called after the episode ended; call reset()")
        if isinstance(action, np.ndarray):
            action = action.item() if action.size == 1 else action
        obs, rewards, terms, truncs, infos = self._par.step({self.agent: action})
        ended = bool(terms.get(self.agent, False) or truncs.get(self.agent, False))
        # All zoo episodes end by a time limit (SPEC §1-2): report it as truncation even if a
        # backend reported termination, so that the value of the last state is bootstrapped.
        self._done = ended
        return (
            np.asarray(obs[self.agent], dtype=np.float32),
            float(rewards[self.agent]),
            False,
            ended,
            dict(infos.get(self.agent, {})),
        )

    def close(self):
        self._par.close()


def _make_single_agent_gs(env_id: str, agent: str, options: dict, in_worker: bool = False) -> SingleAgentGS:
    # Module-level (picklable) factory. In a SubprocVecEnv worker, the worker dies with the
    # training process and leaves Ctrl-C to it (never in the training process itself).
    import torch

    if in_worker:
        from ials_zoo.processes import die_with_parent

        die_with_parent(ignore_sigint=True)
        torch.set_num_threads(1)
    return SingleAgentGS(env_id, agent, **options)


def _safe_subproc_vec_env_class():
    from stable_baselines3.common.vec_env import SubprocVecEnv
    from stable_baselines3.common.vec_env.subproc_vec_env import _stack_obs

    from ials_zoo.processes import recv_from

    class SafeSubprocVecEnv(SubprocVecEnv):
        """SB3's ``SubprocVecEnv`` that never waits forever on a worker: a dead, stopped or
        hung worker raises :class:`ials_zoo.processes.WorkerError` within seconds, and
        ``close()`` kills workers that do not exit promptly."""

        def _recv_all(self):
            return [recv_from(r, p, "SubprocVecEnv worker") for r, p in zip(self.remotes, self.processes)]

        def step_wait(self):
            results = self._recv_all()
            self.waiting = False
            obs, rews, dones, infos, self.reset_infos = zip(*results)
            return _stack_obs(obs, self.observation_space), np.stack(rews), np.stack(dones), infos

        def reset(self):
            for i, remote in enumerate(self.remotes):
                remote.send(("reset", (self._seeds[i], self._options[i])))
            obs, self.reset_infos = zip(*self._recv_all())
            self._reset_seeds()
            self._reset_options()
            return _stack_obs(obs, self.observation_space)

        def close(self):
            if self.closed:
                return
            self.closed = True
            for remote, proc in zip(self.remotes, self.processes):
                try:
                    if self.waiting:
                        recv_from(remote, proc, "SubprocVecEnv worker", timeout=5.0)
                    remote.send(("close", None))
                except Exception:
                    pass
            for proc in self.processes:
                proc.join(timeout=5)
                if proc.is_alive():
                    proc.kill()
                    proc.join(timeout=5)
            for remote in self.remotes:
                remote.close()

    return SafeSubprocVecEnv


def make_gs_vec_env(
    env_id: str,
    agent: str,
    n_envs: int = 8,
    vec_env: str = "auto",
    start_method: str = "spawn",
    **options,
):
    """``n_envs`` copies of :class:`SingleAgentGS` as an SB3 ``VecEnv``.

    Args:
        vec_env: ``"dummy"`` (all copies in this process), ``"subproc"`` (one process per
            copy) or ``"auto"``: subproc for domains that need their own process (SUMO),
            dummy otherwise.
        start_method: multiprocessing start method of the subprocesses (``spawn``: a fresh
            interpreter; a forked child would inherit this process's simulator state).
    """
    from stable_baselines3.common.vec_env import DummyVecEnv

    if n_envs < 1:
        raise ValueError(f"n_envs must be >= 1, got {n_envs}")
    if vec_env not in ("auto", "dummy", "subproc"):
        raise ValueError(f"vec_env must be 'auto', 'dummy' or 'subproc', got {vec_env!r}")
    check_agent(env_id, agent)
    own = needs_own_process(env_id)
    if vec_env == "dummy" and own:
        raise ValueError(
            f"{env_id} holds one simulation per process (libsumo); use vec_env='subproc'"
        )
    subproc = vec_env == "subproc" or (vec_env == "auto" and own)
    fns = [functools.partial(_make_single_agent_gs, env_id, agent, options, subproc) for _ in range(n_envs)]
    if subproc:
        return _safe_subproc_vec_env_class()(fns, start_method=start_method)
    return DummyVecEnv(fns)
