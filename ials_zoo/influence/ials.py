"""Influence-augmented local simulators (IALS, paper §4, Algorithm 2).

An IALS is a domain's local simulator (LS) of one agent's region plus an influence predictor
(AIP). Each step the AIP samples the influence sources ``u_t ~ P(u_t | d_0..d_t)`` and the LS
advances with ``(action, u_t)``.

* :class:`IALSEnv` -- one IALS as a ``gymnasium.Env``;
* :class:`IALSVecEnv` -- ``n_envs`` IALS copies as a stable-baselines3 ``VecEnv`` that advances
  every copy with one batched LS step and one batched AIP call;
* :func:`make_ials` / :func:`make_ials_vec_env` -- build them from ``(env_id, agent)`` and a
  predictor: an :class:`InfluencePredictor` object, or a predictor spec
  (:mod:`ials_zoo.influence.specs`: ``trained``, ``trained:gru|mlp``, ``untrained``,
  ``uniform``, ``fixed:P``, ``marginal`` or a ``.pt`` file). ``trained`` is the AIP shipped
  with the package for the paper's agents (``ials_zoo/influence/pretrained/``), else one
  cached under ``$IALS_ZOO_CACHE/aip/`` (default ``~/.cache/ials_zoo/aip/``), else collected
  and trained on demand (Algorithm 1, 50,000 steps, with progress bars) and cached.

Episodes end only by truncation after the LS's ``max_cycles`` steps.
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

from ials_zoo.core.domains import Domain, get_domain
from ials_zoo.core.region import check_dset_kind
from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.influence.base import InfluencePredictor
from ials_zoo.influence.constant import FixedPredictor, MarginalPredictor, UniformPredictor
from ials_zoo.influence.dataset import collect_regions
from ials_zoo.influence.files import load_predictor, save_predictor
from ials_zoo.influence.networks import untrained_predictor
from ials_zoo.influence.specs import PredictorSpec, parse_predictor
from ials_zoo.influence.train import format_report, train_predictor
from ials_zoo.utils import check_seed

PRETRAINED_DIR = Path(__file__).resolve().parent / "pretrained"
DEFAULT_COLLECT_STEPS = 50_000


class IALSEnv(gym.Env):
    """Influence-augmented local simulator of one agent (paper Algorithm 2), a Gymnasium env.

    The agent sees exactly what it sees in the global simulator: same observation and action
    spaces, same reward. Only its region is simulated; the rest of the system is replaced by
    the influence predictor, which samples the influence sources each step from the d-set
    history of the episode.

    Action / observation / reward: those of the domain's agent (see the GS's documentation).

    Episode end: truncation after ``max_cycles`` steps (``terminated`` is always False).

    ``info`` after a step holds ``"influence"``, the sampled ``u_t`` (int64, ``(M,)``).

    Version history: v0 -- first version.
    """

    metadata = {"render_modes": []}

    def __init__(self, local_simulator, predictor: InfluencePredictor, seed: int | None = None):
        if local_simulator.n_copies != 1:
            raise BadInput(f"IALSEnv needs a local simulator with one copy, got {local_simulator.n_copies}")
        _check_compatible(local_simulator, predictor)
        self.ls = local_simulator
        self.predictor = predictor
        self.observation_space = local_simulator.observation_space
        self.action_space = local_simulator.action_space
        self.max_cycles = int(local_simulator.max_cycles)
        self.region = local_simulator.region
        self.render_mode = None
        self._kind = predictor.dset_kind
        self._seed = check_seed(seed)
        self._t = 0
        self._d = None
        self._actions = np.zeros(1, dtype=np.int64)
        # A local simulator with a single-copy fast path is stepped through it: same
        # results, without building batched arrays per step.
        self._fast = bool(local_simulator.supports_step_single)
        if self._fast:
            self._step_single = local_simulator.step_single
            self._observe_single = local_simulator.observe_single
            self._n_actions = int(self.action_space.n)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        # Gymnasium's semantics: the constructor's seed stands for the first reset's; any
        # reset consumes it, so an explicit reset(seed=s) is never followed by a replay of it.
        seed = check_seed(seed)
        if seed is None:
            seed = self._seed
        self._seed = None
        super().reset(seed=seed)
        # Separate streams for the LS and the AIP, both determined by ``seed``.
        ls_seed = None if seed is None else int(np.random.SeedSequence(seed).generate_state(1)[0])
        obs, dsets = self.ls.reset(seed=ls_seed)
        self.predictor.reset(1)
        self._d = dsets[self._kind]
        self._t = 0
        return obs[0], {}

    def step(self, action):
        if self._d is None:
            raise RuntimeError("call reset() before step()")
        if self._t >= self.max_cycles:
            raise RuntimeError("the episode is over (truncated); call reset()")
        if self._fast:
            return self._step_fast(action)
        u = self.predictor.sample(self._d, self.np_random)
        self._actions[0] = _scalar_action(action)
        obs, rewards, dsets = self.ls.step(self._actions, u)
        self._d = dsets[self._kind]
        self._t += 1
        truncated = self._t >= self.max_cycles
        return obs[0], float(rewards[0]), False, truncated, {"influence": u[0]}

    def _step_fast(self, action):
        if type(action) is int or isinstance(action, np.integer):
            a = int(action)
        else:
            a = int(_scalar_action(action))
        if not 0 <= a < self._n_actions:
            raise BadInput(f"actions must be in 0..{self._n_actions - 1}, got values {a}..{a}")
        rng = self._np_random  # the np_random property's lazy creation, without its cost
        if rng is None:
            rng = self.np_random
        u = self.predictor.sample(self._d, rng)[0]
        reward = self._step_single(a, *u.tolist())
        obs, dsets = self._observe_single()
        self._d = dsets[self._kind]
        self._t += 1
        return obs.copy(), reward, False, self._t >= self.max_cycles, {"influence": u}

    def close(self):
        self.ls.close()


def _scalar_action(action):
    a = np.asarray(action)
    if a.size != 1 or a.dtype.kind not in "iu":
        raise BadInput(f"expected one integer action, got {action!r}")
    return a.reshape(())


def _check_compatible(ls, predictor):
    if not isinstance(predictor, InfluencePredictor):
        raise BadInputType(f"predictor must be an InfluencePredictor, got {type(predictor).__name__}")
    a, b = predictor.region, ls.region
    if (a.domain, a.agent) != (b.domain, b.agent):
        raise BadInput(
            f"the influence predictor is for {a.domain}/{a.agent} but the local simulator is "
            f"{b.domain}/{b.agent}"
        )
    if a.to_dict() != b.to_dict():
        diff = {
            k: (a.to_dict()[k], b.to_dict()[k]) for k in a.to_dict() if a.to_dict()[k] != b.to_dict()[k]
        }
        raise BadInput(
            f"the influence predictor for {a.domain}/{a.agent} was built for another region "
            f"setting (predictor vs local simulator: {diff})"
        )


try:
    from stable_baselines3.common.vec_env.base_vec_env import VecEnv as _VecEnvBase
except ImportError:  # pragma: no cover - SB3 is a dependency, keep import errors readable
    _VecEnvBase = object


class IALSVecEnv(_VecEnvBase):
    """``n_envs`` IALS copies of one agent as a stable-baselines3 ``VecEnv``.

    All copies advance together: one batched LS step and one batched AIP call per
    ``step``. Since every episode lasts exactly ``max_cycles`` steps, all copies truncate at
    the same step and are reset together (auto-reset, as SB3 expects): the returned
    observations are the new episode's, ``infos[i]["terminal_observation"]`` is the last
    observation of the finished one, ``infos[i]["TimeLimit.truncated"]`` is True (so SB3
    bootstraps the value of the truncated state) and ``infos[i]["episode"]`` holds
    ``{"r": return, "l": length, "t": seconds since creation}`` (SB3's Monitor format, so
    episode statistics are logged without a Monitor wrapper).

    ``get_attr``/``set_attr``/``env_method`` act on this object itself (the copies have no
    separate env objects); ``env_method`` calls the method once and repeats the result.
    """

    def __init__(self, local_simulator, predictor: InfluencePredictor, seed: int | None = None):
        _check_compatible(local_simulator, predictor)
        self.ls = local_simulator
        self.predictor = predictor
        self.region = local_simulator.region
        self.max_cycles = int(local_simulator.max_cycles)
        self.render_mode = None
        n = int(local_simulator.n_copies)
        super().__init__(n, local_simulator.observation_space, local_simulator.action_space)
        self._kind = predictor.dset_kind
        self._rng = np.random.default_rng(check_seed(seed))
        self._next_seed = seed
        self._t = 0
        self._d = None
        self._actions = None
        self._returns = np.zeros(n)
        self._t_start = time.perf_counter()

    def reset(self):
        seed = self._seeds[0] if self._seeds[0] is not None else self._next_seed
        self._next_seed = None
        self._reset_seeds()
        self._reset_options()
        return self._reset(seed)

    def _reset(self, seed=None):
        if seed is not None:
            ss = np.random.SeedSequence(seed)
            ls_seed, aip_seed = (int(s) for s in ss.generate_state(2))
            self._rng = np.random.default_rng(aip_seed)
        else:
            ls_seed = None
        obs, dsets = self.ls.reset(seed=ls_seed)
        self.predictor.reset(self.num_envs)
        self._d = dsets[self._kind]
        self._t = 0
        self._returns[:] = 0.0
        return obs

    def step_async(self, actions):
        self._actions = actions

    def step_wait(self):
        if self._d is None:
            raise RuntimeError("call reset() before step()")
        actions = np.asarray(self._actions)
        if actions.ndim > 1:
            actions = actions.reshape(self.num_envs)
        u = self.predictor.sample(self._d, self._rng)
        obs, rewards, dsets = self.ls.step(actions, u)
        self._d = dsets[self._kind]
        self._t += 1
        self._returns += rewards
        rewards = np.asarray(rewards, dtype=np.float32)
        if self._t < self.max_cycles:
            return obs, rewards, np.zeros(self.num_envs, dtype=bool), [{} for _ in range(self.num_envs)]
        t = round(time.perf_counter() - self._t_start, 6)
        infos = [
            {
                "terminal_observation": obs[i],
                "TimeLimit.truncated": True,
                "episode": {"r": float(self._returns[i]), "l": self._t, "t": t},
            }
            for i in range(self.num_envs)
        ]
        new_obs = self._reset(None)
        return new_obs, rewards, np.ones(self.num_envs, dtype=bool), infos

    def close(self):
        self.ls.close()

    def seed(self, seed=None):
        if seed is None:
            seed = int(np.random.randint(0, np.iinfo(np.uint32).max, dtype=np.uint32))
        self._seeds = [seed + i for i in range(self.num_envs)]
        return self._seeds

    def get_attr(self, attr_name, indices=None):
        return [getattr(self, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name, value, indices=None):
        setattr(self, attr_name, value)

    def env_method(self, method_name, *method_args, indices=None, **method_kwargs):
        result = getattr(self, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None):
        return [False for _ in self._get_indices(indices)]

    def get_images(self):
        return [None for _ in range(self.num_envs)]


# --------------------------------------------------------------------------------------------
# Factories
# --------------------------------------------------------------------------------------------


def cache_dir() -> Path:
    """Where on-demand AIPs are cached: ``$IALS_ZOO_CACHE/aip`` or ``~/.cache/ials_zoo/aip``."""
    root = os.environ.get("IALS_ZOO_CACHE")
    return (Path(root) if root else Path.home() / ".cache" / "ials_zoo") / "aip"


def pretrained_path(env_id: str, agent: str) -> Path:
    """The package-data path of the shipped AIP of ``agent`` (may not exist)."""
    return PRETRAINED_DIR / f"{env_id}__{agent}.pt"


def _cache_path(region, arch: str, dset_kind: str) -> Path:
    key = json.dumps(region.to_dict(), sort_keys=True)
    h = hashlib.sha256(key.encode()).hexdigest()[:12]
    return cache_dir() / f"{region.domain}__{region.agent}__{arch}__{dset_kind}__{h}.pt"


def _matches(pred, region, dset_kind) -> bool:
    return pred.dset_kind == dset_kind and pred.region.to_dict() == region.to_dict()


def trained_predictor(
    env_id: str | Domain,
    agent: str,
    dset_kind: str = "dset",
    arch: str | None = None,
    options: dict | None = None,
    train_if_missing: bool = False,
    progress: bool = True,
    steps: int = DEFAULT_COLLECT_STEPS,
) -> InfluencePredictor:
    """The trained AIP of ``agent``: shipped, else cached, else (``train_if_missing`` only)
    collected + trained + cached; without it a FileNotFoundError says how to train one.

    A shipped/cached AIP is used only if it was trained for exactly this region setting
    (``RegionSpec`` incl. its params), d-set kind and architecture (default: the domain's).
    ``env_id``: a domain id or the :class:`~ials_zoo.core.domains.Domain` itself.
    """
    return trained_aip(get_domain(env_id), agent, dset_kind, arch, options, train_if_missing, progress, steps)


def trained_aip(domain: Domain, agent: str, dset_kind: str = "dset", arch: str | None = None,
                options: dict | None = None, train_if_missing: bool = False, progress: bool = True,
                steps: int = DEFAULT_COLLECT_STEPS) -> InfluencePredictor:
    """:func:`trained_predictor` of a resolved :class:`~ials_zoo.core.domains.Domain`."""
    domain = domain.require_local_simulator("make_ials")
    dset_kind, options, env_id = check_dset_kind(dset_kind), dict(options or {}), domain.env_id
    region = domain.region_spec(agent, **options)
    arch = arch or domain.default_predictor
    for path in (pretrained_path(env_id, agent), _cache_path(region, arch, dset_kind)):
        if path.is_file():
            pred = load_predictor(path, env_id=env_id, agent=agent)
            if _matches(pred, region, dset_kind) and pred.name == arch:
                return pred
    if not train_if_missing:
        raise FileNotFoundError(
            f"no trained influence predictor for {env_id}/{agent} ({dset_kind!r} d-set, "
            f"options {options}); train one with `ials-zoo train-aip --env {env_id} --agent {agent}"
            f"{_options_flag(options)} --out FILE` "
            "and pass its file, or ask for predictor='train' (`--predictor train` on the command line) to have it "
            "collected and trained now (minutes)"
        )

    print(
        f"ials_zoo: no trained AIP for {env_id}/{agent} ({dset_kind!r} d-set); collecting "
        f"{steps} steps and training one (cached in {cache_dir()})"
    )
    data = collect_regions(domain, [agent], steps=steps, gs_options=options, progress=progress)[agent]
    pred, report = train_predictor(data, arch=arch, dset_kind=dset_kind, progress=progress)
    print(format_report(report))
    save_predictor(pred, _cache_path(region, arch, dset_kind))
    return pred


def _options_flag(options: dict) -> str:
    """`` --options '<json>'`` for a command line, or nothing without options."""
    return f" --options '{json.dumps(options, sort_keys=True)}'" if options else ""


def resolve_predictor(
    predictor,
    env_id: str | Domain,
    agent: str,
    dset_kind: str | None = None,
    seed: int | None = None,
    options: dict | None = None,
) -> InfluencePredictor:
    """Turn a predictor (object, path, spec text or parsed :class:`PredictorSpec`, see
    :mod:`ials_zoo.influence.specs`) into a predictor for ``agent`` of ``env_id`` (an id or
    the :class:`~ials_zoo.core.domains.Domain`)."""
    return _resolve(get_domain(env_id), agent, predictor, dset_kind, seed, dict(options or {}))


def _resolve(domain: Domain, agent: str, predictor, dset_kind: str | None, seed: int | None,
             options: dict) -> InfluencePredictor:
    """:func:`resolve_predictor` with its domain resolved."""
    env_id = domain.env_id
    kind = check_dset_kind(dset_kind or "dset")
    if isinstance(predictor, InfluencePredictor):
        pred = copy.deepcopy(predictor)  # a private copy: the recurrent state must not be shared between envs
    elif isinstance(predictor, (str, os.PathLike, PredictorSpec)):
        spec = predictor if isinstance(predictor, PredictorSpec) else parse_predictor(predictor)
        pred = _from_spec(domain, agent, spec, kind, seed, options)
    else:
        raise BadInputType(
            f"predictor must be a name, a path or an InfluencePredictor, got {type(predictor).__name__}"
        )
    if pred.region.domain != env_id or pred.region.agent != agent:
        raise BadInput(
            f"the influence predictor is for {pred.region.domain}/{pred.region.agent}, not "
            f"{env_id}/{agent}"
        )
    if dset_kind is not None and pred.dset_kind != kind:
        raise BadInput(f"the influence predictor reads the {pred.dset_kind!r} d-set, not {dset_kind!r}")
    return pred


def _from_spec(domain: Domain, agent: str, spec: PredictorSpec, kind: str, seed: int | None,
               options: dict) -> InfluencePredictor:
    """The predictor a parsed spec names (module :mod:`ials_zoo.influence.specs`)."""
    if spec.kind == "file":
        return load_predictor(spec.path, env_id=domain.env_id, agent=agent)
    if spec.kind == "trained":
        return trained_aip(domain, agent, kind, spec.arch, options, spec.train_if_missing)
    region = domain.region_spec(agent, **options)
    if spec.kind == "uniform":
        return UniformPredictor(region, dset_kind=kind, probs=domain.untrained_probs)
    if spec.kind == "untrained":
        return untrained_predictor(region, arch=domain.default_predictor, dset_kind=kind,
                                   seed=0 if seed is None else seed)
    if spec.kind == "fixed":
        return FixedPredictor(region, spec.p, dset_kind=kind, null_class=domain.null_influence)
    trained = trained_aip(domain, agent, kind, None, options)  # marginal
    marg = trained.metadata.get("marginal")
    if marg is None:
        raise BadInput(
            f"the trained AIP of {domain.env_id}/{agent} carries no data marginal; build a "
            "MarginalPredictor.fit(dataset) from collected data instead"
        )
    return MarginalPredictor(region, marg, dset_kind=kind, metadata={"from": "trained AIP data"})


def make_ials(
    env_id: str | Domain,
    agent: str,
    predictor="trained",
    dset_kind: str | None = None,
    seed: int | None = None,
    render_mode: str | None = None,
    **options,
) -> IALSEnv:
    """The IALS of ``agent`` in domain ``env_id`` as a Gymnasium env.

    Args:
        env_id: domain id, e.g. ``"warehouse_v0"`` (or the :class:`~ials_zoo.core.domains.Domain`).
        agent: the agent whose region is simulated, e.g. ``"robot_20"``.
        predictor: an :class:`InfluencePredictor`, a path, or a name (module docstring).
        dset_kind: d-set the AIP reads (``"dset"`` default, ``"full"`` for the ablation).
        seed: seeds the first ``reset`` (LS and AIP sampling) and ``"untrained"`` weights.
        **options: domain options, passed to the local simulator (and to the GS when an AIP
            has to be trained on demand), e.g. ``item_lifetime=8``.
    """
    if render_mode is not None:
        raise BadInput(f"IALS envs do not render; got render_mode={render_mode!r}")
    domain = get_domain(env_id).require_local_simulator("make_ials")
    domain.check_agent(agent, **options)
    pred = _resolve(domain, agent, predictor, dset_kind, seed, options)
    ls = domain.local_simulator(agent, n_envs=1, **options)
    try:
        return IALSEnv(ls, pred, seed=seed)
    except BaseException:
        ls.close()
        raise


def gymnasium_entry_point(env_id: str, agent: str | None = None, **kwargs) -> IALSEnv:
    """Entry point of ``gymnasium.make("ials_zoo/IALS-<env_id>", agent=..., ...)``: the
    arguments of :func:`make_ials`; ``agent`` defaults to the domain's first paper agent."""
    if agent is None:
        agent = get_domain(env_id).default_agents[0]
    return make_ials(env_id, agent, **kwargs)


def make_ials_vec_env(
    env_id: str | Domain,
    agent: str,
    n_envs: int = 8,
    predictor="trained",
    dset_kind: str | None = None,
    seed: int | None = None,
    **options,
) -> IALSVecEnv:
    """``n_envs`` IALS copies of ``agent`` as an SB3 ``VecEnv`` (one batched AIP call per step).

    Arguments as :func:`make_ials`. The predictor object is used by this VecEnv alone (its
    recurrent state holds the ``n_envs`` histories): do not share it with another env.
    """
    return ials_vec_env(get_domain(env_id), agent, n_envs, predictor, dset_kind, seed, **options)


def ials_vec_env(domain: Domain, agent: str, n_envs: int = 8, predictor="trained", dset_kind: str | None = None,
                 seed: int | None = None, **options) -> IALSVecEnv:
    """:func:`make_ials_vec_env` of a resolved :class:`~ials_zoo.core.domains.Domain`."""
    if isinstance(n_envs, bool) or not isinstance(n_envs, (int, np.integer)) or n_envs < 1:
        raise BadInput(f"n_envs must be a positive int, got {n_envs!r}")
    domain = domain.require_local_simulator("make_ials_vec_env")
    domain.check_agent(agent, **options)
    pred = _resolve(domain, agent, predictor, dset_kind, seed, options)
    ls = domain.local_simulator(agent, n_envs=int(n_envs), **options)
    try:
        return IALSVecEnv(ls, pred, seed=seed)
    except BaseException:
        ls.close()
        raise


__all__ = [
    "IALSEnv",
    "IALSVecEnv",
    "cache_dir",
    "ials_vec_env",
    "make_ials",
    "make_ials_vec_env",
    "pretrained_path",
    "resolve_predictor",
    "trained_aip",
    "trained_predictor",
]
