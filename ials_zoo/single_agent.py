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

from ials_zoo.core.domains import Domain, get_domain
from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.runtime.processes import Worker, call_all, start_all


def box_space(space: spaces.Space) -> spaces.Box:
    """The float32 ``Box`` the baselines see for a GS/LS observation space."""
    if isinstance(space, spaces.MultiBinary):
        return spaces.Box(0.0, 1.0, shape=tuple(np.atleast_1d(space.n)), dtype=np.float32)
    if isinstance(space, spaces.Box):
        return spaces.Box(
            space.low.astype(np.float32), space.high.astype(np.float32), dtype=np.float32
        )
    raise BadInputType(
        f"observation space {space!r} is not supported by the baselines; expected a Box or "
        "MultiBinary"
    )


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
        self.agent = get_domain(env_id).check_agent(agent, **options)
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
    # Module-level (picklable) factory; a worker process of make_gs_vec_env runs one env on
    # one thread
    import torch

    if in_worker:
        torch.set_num_threads(1)
    return SingleAgentGS(env_id, agent, **options)


class _EnvServer:
    """One gymnasium env in a :class:`~ials_zoo.runtime.processes.Worker`, answering what SB3's
    ``SubprocVecEnv`` worker answers (auto-reset after an episode's end included)."""

    def __init__(self, env_fn):
        self.env = env_fn()

    def spaces(self):
        return self.env.observation_space, self.env.action_space

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        done = terminated or truncated
        info["TimeLimit.truncated"] = truncated and not terminated
        reset_info = {}
        if done:
            info["terminal_observation"] = observation
            observation, reset_info = self.env.reset()
        return observation, reward, done, info, reset_info

    def reset(self, seed, options):
        return self.env.reset(seed=seed, **({"options": options} if options else {}))

    def render(self):
        return self.env.render()

    def get_attr(self, name):
        return self.env.get_wrapper_attr(name)

    def has_attr(self, name):
        try:
            self.env.get_wrapper_attr(name)
            return True
        except AttributeError:
            return False

    def set_attr(self, name, value):
        setattr(self.env, name, value)

    def env_method(self, name, args, kwargs):
        return self.env.get_wrapper_attr(name)(*args, **kwargs)

    def is_wrapped(self, wrapper_class):
        from stable_baselines3.common.env_util import is_wrapped

        return is_wrapped(self.env, wrapper_class)

    def close(self):
        self.env.close()


def _worker_vec_env_class():
    from stable_baselines3.common.vec_env import VecEnv
    from stable_baselines3.common.vec_env.subproc_vec_env import _stack_obs

    class WorkerVecEnv(VecEnv):
        """SB3's ``SubprocVecEnv`` on :class:`ials_zoo.runtime.processes.Worker`: one env per worker
        process (fresh interpreters dying with this one), and never a wait without end: a
        dead, stopped or hung worker raises :class:`ials_zoo.runtime.processes.WorkerError` within
        seconds, and ``close()`` kills workers that do not exit promptly."""

        def __init__(self, env_fns):
            self.workers = [Worker(_EnvServer, (fn,), name=f"env worker {i}") for i, fn in enumerate(env_fns)]
            start_all(self.workers)
            self.closed = False
            observation_space, action_space = self.workers[0].call("spaces")
            super().__init__(len(env_fns), observation_space, action_space)

        def _call(self, method, args=None, indices=None):
            chosen = [self.workers[i] for i in self._get_indices(indices)]
            return call_all(chosen, method, args)

        def step_async(self, actions):
            for w, action in zip(self.workers, actions):
                w.send("step", action)

        def step_wait(self):
            try:
                results = [w.receive() for w in self.workers]
            except BaseException:
                self.close(kill=True)
                raise
            obs, rews, dones, infos, self.reset_infos = zip(*results)
            return _stack_obs(obs, self.observation_space), np.stack(rews), np.stack(dones), infos

        def reset(self):
            results = self._call("reset", [(self._seeds[i], self._options[i]) for i in range(self.num_envs)])
            obs, self.reset_infos = zip(*results)
            self._reset_seeds()
            self._reset_options()
            return _stack_obs(obs, self.observation_space)

        def get_images(self):
            return self._call("render")

        def has_attr(self, attr_name):
            return all(self._call("has_attr", [(attr_name,)] * self.num_envs))

        def get_attr(self, attr_name, indices=None):
            n = len(self._get_indices(indices))
            return self._call("get_attr", [(attr_name,)] * n, indices)

        def set_attr(self, attr_name, value, indices=None):
            n = len(self._get_indices(indices))
            self._call("set_attr", [(attr_name, value)] * n, indices)

        def env_method(self, method_name, *method_args, indices=None, **method_kwargs):
            n = len(self._get_indices(indices))
            return self._call("env_method", [(method_name, method_args, method_kwargs)] * n, indices)

        def env_is_wrapped(self, wrapper_class, indices=None):
            n = len(self._get_indices(indices))
            return self._call("is_wrapped", [(wrapper_class,)] * n, indices)

        def close(self, kill: bool = False):
            if self.closed:
                return
            self.closed = True
            for w in self.workers:
                w.close(kill=kill)

    return WorkerVecEnv


def make_gs_vec_env(
    env_id: str | Domain,
    agent: str,
    n_envs: int = 8,
    vec_env: str = "auto",
    **options,
):
    """``n_envs`` copies of :class:`SingleAgentGS` as an SB3 ``VecEnv``.

    Args:
        vec_env: ``"dummy"`` (all copies in this process), ``"subproc"`` (one process per
            copy) or ``"auto"``: subproc for domains that need their own process (SUMO),
            dummy otherwise.
    """
    return gs_vec_env(get_domain(env_id), agent, n_envs, vec_env, **options)


def gs_vec_env(domain: Domain, agent: str, n_envs: int = 8, vec_env: str = "auto", **options):
    """:func:`make_gs_vec_env` of a resolved :class:`~ials_zoo.core.domains.Domain`."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    if n_envs < 1:
        raise BadInput(f"n_envs must be >= 1, got {n_envs}")
    if vec_env not in ("auto", "dummy", "subproc"):
        raise BadInput(f"vec_env must be 'auto', 'dummy' or 'subproc', got {vec_env!r}")
    env_id = domain.env_id  # what the env factories (and worker processes) are given
    domain.check_agent(agent)
    own = domain.one_simulation_per_process
    if vec_env == "dummy" and own:
        raise BadInput(
            f"{env_id} holds one simulation per process (libsumo); use vec_env='subproc'"
        )
    subproc = vec_env == "subproc" or (vec_env == "auto" and own)
    fns = [functools.partial(_make_single_agent_gs, env_id, agent, options, subproc) for _ in range(n_envs)]
    if subproc:
        return _worker_vec_env_class()(fns)
    return DummyVecEnv(fns)
