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
marked so in :func:`needs_own_process`).
"""

from __future__ import annotations

import functools
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from ials_zoo.core.domains import get_domain

# Domains whose GS holds a process-wide resource (libsumo: one simulation per process), so
# that two instances must never live in the same process.
_ONE_PER_PROCESS = {"traffic_grid_v0"}


def needs_own_process(env_id: str) -> bool:
    """True when each GS of ``env_id`` must live in its own process (SUMO via libsumo)."""
    dom = get_domain(env_id)
    return env_id in _ONE_PER_PROCESS or bool(dom.extra.get("one_per_process", False))


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
    """Raise a ValueError naming the domain's agents when ``agent`` is not one of them."""
    import inspect

    possible = get_domain(env_id).possible_agents
    # possible_agents takes only the options that shape the agent set (e.g. robots=(R, C)).
    params = inspect.signature(possible).parameters
    if not any(p.kind is p.VAR_KEYWORD for p in params.values()):
        options = {k: v for k, v in options.items() if k in params}
    agents = list(possible(**options))
    if agent not in agents:
        shown = ", ".join(agents[:6]) + (", ..." if len(agents) > 6 else "")
        raise ValueError(f"unknown agent {agent!r} for {env_id}; expected one of: {shown}")
    return agent


class SingleAgentGS(gymnasium.Env):
    """The GS of ``env_id`` from the point of view of ``agent``; every other agent is scripted.

    Args:
        env_id: versioned domain id (``"warehouse_v0"``, ``"traffic_grid_v0"``).
        agent: the learning agent (e.g. ``"robot_20"``, ``"intersection_12"``).
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


def _make_single_agent_gs(env_id: str, agent: str, options: dict) -> SingleAgentGS:
    # Module-level (picklable) factory for SubprocVecEnv workers.
    import torch

    torch.set_num_threads(1)
    return SingleAgentGS(env_id, agent, **options)


def make_gs_vec_env(
    env_id: str,
    agent: str,
    n_envs: int = 8,
    vec_env: str = "auto",
    start_method: str = "forkserver",
    **options,
):
    """``n_envs`` copies of :class:`SingleAgentGS` as an SB3 ``VecEnv``.

    Args:
        vec_env: ``"dummy"`` (all copies in this process), ``"subproc"`` (one process per
            copy) or ``"auto"``: subproc for domains that need their own process (SUMO),
            dummy otherwise.
        start_method: multiprocessing start method of the subprocesses (``forkserver`` or
            ``spawn``: a forked child would inherit this process's simulator state).
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

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
    fns = [functools.partial(_make_single_agent_gs, env_id, agent, options) for _ in range(n_envs)]
    if vec_env == "subproc" or (vec_env == "auto" and own):
        return SubprocVecEnv(fns, start_method=start_method)
    return DummyVecEnv(fns)
