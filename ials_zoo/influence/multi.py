"""The multi-agent IALS: every agent on its own local simulator and AIP, all in one batch.

Every agent (default: all of the GS's) gets its own local simulator and its own AIP; agents
interact only through their AIPs. One step is one batched computation: the domain's local
simulator holds every agent's region (:class:`~ials_zoo.core.LocalSimulator` with several
agents) and the AIPs are one :class:`~ials_zoo.influence.stacked.StackedPredictor`.

* :class:`IALSParallelEnv` -- one copy per agent as a PettingZoo ``ParallelEnv``: spaces,
  rewards and infos (``influence``, ``dset``, ``dset_full``) are the GS's, so code that trains
  on the GS runs unchanged on it (:func:`make_ials_parallel_env`);
* :class:`MultiAgentIALS` -- ``n_envs`` copies per agent, arrays in and out
  (``[agents, n_envs, ...]``), what DIALS trains on.

Randomness is per (agent, copy) (:mod:`ials_zoo.core.streams`): given the same seed and the
same influence sources, each agent's trajectory equals its single-agent IALS's
(:func:`ials_zoo.make_ials`).

AIPs for every agent (``predictor="trained"``): the set shipped with the package
(``pretrained/<env_id>__all.pt``, trained on one GS run in which every agent acted uniformly at
random -- DIALS's starting point), else one cached under ``$IALS_ZOO_CACHE/aip/``, else collected
(one GS run records every region at once) and trained on demand. ``"untrained"``,
``"uniform"``, ``"fixed:P"`` and predictor objects work as for one agent; a dict
``{agent: predictor}`` or a predictor-set file gives each agent its own.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from ials_zoo.core.domains import get_domain
from ials_zoo.core.extras import dials_of
from ials_zoo.core.region import INFLUENCE_KEY, check_dset_kind
from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.influence import dataset
from ials_zoo.influence.base import InfluencePredictor
from ials_zoo.influence.files import load_predictor_set, save_predictor_set
from ials_zoo.influence.ials import PRETRAINED_DIR, cache_dir, resolve_predictor
from ials_zoo.influence.specs import parse_predictor
from ials_zoo.influence.stacked import StackedPredictor
from ials_zoo.influence.train import train_predictors
from ials_zoo.utils import check_reset_options, check_seed

SET_SUFFIX = "__all.pt"


def shipped_set_path(env_id: str) -> Path:
    """The package-data path of the shipped AIPs of every agent of ``env_id`` (may not exist)."""
    return PRETRAINED_DIR / f"{env_id}{SET_SUFFIX}"


def _set_cache_path(env_id, regions, arch, dset_kind) -> Path:
    key = json.dumps([r.to_dict() for r in regions], sort_keys=True)
    h = hashlib.sha256(key.encode()).hexdigest()[:12]
    return cache_dir() / f"{env_id}__all__{arch}__{dset_kind}__{h}.pt"


def trained_predictor_set(env_id: str, agents=None, dset_kind: str = "dset", options: dict | None = None,
                          train_if_missing: bool = False, progress: bool = True, steps: int | None = None) -> dict:
    """``{agent: AIP}`` of every agent: shipped, else cached, else trained (module docstring).
    A shipped or cached set is used only if it was trained for exactly these regions (their
    ``RegionSpec`` incl. params) and d-set kind."""
    domain = get_domain(env_id)
    options = dict(options or {})
    agents = domain.check_agents(agents, **options)
    regions = {a: domain.region_spec(a, **options) for a in agents}
    arch = dials_of(domain).aip_arch
    for path in (shipped_set_path(env_id), _set_cache_path(env_id, list(regions.values()), arch, dset_kind)):
        if path.is_file():
            found = load_predictor_set(path, env_id=env_id)
            if all(a in found and found[a].region == regions[a] and found[a].dset_kind == dset_kind for a in agents):
                return {a: found[a] for a in agents}
    if not train_if_missing:
        raise FileNotFoundError(f"no trained AIPs for the agents of {env_id} (options {options}); train them with "
                                f"`ials-zoo train-aip --env {env_id} --agent all --out FILE.pt` and pass the file, "
                                "or ask for predictor='train' (`--predictor train` on the command line) to have "
                                "them collected and trained now (minutes)")

    d = dials_of(domain)
    steps = steps or 50_000
    print(f"ials_zoo: no trained AIPs for every agent of {env_id}; collecting {steps} GS steps (all agents "
          f"random) and training {len(domain.agents(**options))} {arch} AIPs (cached in {cache_dir()})")
    everyone = domain.agents(**options)
    data = dataset.collect_all(env_id, everyone, steps=steps, gs_options=options, progress=progress)
    preds, _ = train_predictors(data, arch, hidden=d.aip_hidden, lr=d.aip_lr, epochs=d.aip_epochs, batch_size=d.aip_batch,
                                dset_kind=dset_kind, progress=progress, lr_schedule=d.aip_lr_schedule)
    save_predictor_set(preds.values(), _set_cache_path(env_id, [regions.get(a) or domain.region_spec(a, **options)
                                                                for a in everyone], arch, dset_kind),
                       metadata={"steps": steps, "policy": "uniform_random (every agent)"})
    return {a: preds[a] for a in agents}


def resolve_predictor_set(predictor, env_id: str, agents, dset_kind: str | None = None, seed: int | None = None,
                          options: dict | None = None) -> list[InfluencePredictor]:
    """One predictor per agent (in ``agents`` order) from a spec (see the module docstring)."""
    options = dict(options or {})
    kind = check_dset_kind(dset_kind or "dset")
    if isinstance(predictor, StackedPredictor):
        predictor = dict(zip(predictor.agents, predictor.predictors))
    if isinstance(predictor, dict):
        missing = [a for a in agents if a not in predictor]
        if missing:
            raise BadInput(f"no influence predictor for {missing}")
        return [resolve_predictor(predictor[a], env_id, a, dset_kind, seed, options) for a in agents]
    if isinstance(predictor, (str, os.PathLike)):
        spec = parse_predictor(predictor)
        if spec.kind == "file":
            found = load_predictor_set(spec.path, env_id=env_id)
            return resolve_predictor_set(found, env_id, agents, dset_kind, seed, options)
        if spec.kind == "trained" and spec.arch is None:
            found = trained_predictor_set(env_id, agents, kind, options, train_if_missing=spec.train_if_missing)
            return [found[a] for a in agents]
    return [resolve_predictor(predictor, env_id, a, dset_kind, seed, options) for a in agents]


def _ls_seed(seed: int | None) -> int | None:
    # as the single-agent IALSEnv derives its local simulator's seed
    return None if seed is None else int(np.random.SeedSequence(seed).generate_state(1)[0])


class MultiAgentIALS:
    """``n_envs`` IALS copies of each of ``agents``, stepped as one batch (module docstring).

    Arrays are ``[agents, n_envs, ...]``. ``step`` returns the new observations, rewards, and
    ``done`` (every copy truncates together after ``max_cycles`` steps: the caller resets).
    """

    def __init__(self, local_simulator, predictor: StackedPredictor):
        if list(predictor.agents) != list(local_simulator.agents) or predictor.n_envs != local_simulator.n_envs:
            raise BadInput("the stacked predictor must hold the local simulator's agents and copies")
        for p, r in zip(predictor.predictors, local_simulator.regions):
            if p.region.to_dict() != r.to_dict():
                raise BadInput(f"the influence predictor of {r.agent} was built for another region setting")
        self.ls, self.predictor = local_simulator, predictor
        self.agents = list(local_simulator.agents)
        self.n_envs = local_simulator.n_envs
        self.max_cycles = int(local_simulator.max_cycles)
        self.kind = predictor.dset_kind
        self.t = 0
        self._d = None

    def _shape(self, x):
        return x.reshape(len(self.agents), self.n_envs, *x.shape[1:])

    def reset(self, seed: int | None = None):
        """New episodes in every copy; ``(obs, dsets)`` with ``dsets[kind] [A, n, D]``."""
        seed = check_seed(seed)
        obs, dsets = self.ls.reset(seed=_ls_seed(seed))
        if seed is not None:
            self.predictor.seed(seed)
        self.predictor.reset()
        self._d = dsets[self.kind]
        self.t = 0
        return self._shape(obs), {k: self._shape(v) for k, v in dsets.items()}

    def step(self, actions):
        """``actions [A, n]`` -> ``(obs, rewards, dsets, influences, done)``."""
        if self._d is None:
            raise RuntimeError("call reset() before step()")
        u = self.predictor.sample(self._d)
        obs, rewards, dsets = self.ls.step(np.asarray(actions).reshape(-1), u)
        self._d = dsets[self.kind]
        self.t += 1
        return (self._shape(obs), self._shape(np.asarray(rewards)), {k: self._shape(v) for k, v in dsets.items()},
                self._shape(u), self.t >= self.max_cycles)

    def set_predictors(self, predictors: dict) -> None:
        """Replace some agents' AIPs (DIALS's retraining); effective from the next step."""
        self.predictor.replace(predictors)

    def close(self):
        self.ls.close()


class IALSParallelEnv(ParallelEnv):
    """The multi-agent IALS of a domain as a PettingZoo ``ParallelEnv`` (module docstring).

    Agents, action and observation spaces, rewards and infos are the GS's; there are no
    scripted agents. Episode end: truncation after the domain's episode length (never
    termination). ``state()`` is the agents' observations concatenated (a local simulator has
    no global state). ``infos[a]["influence"]`` is the ``u_t`` the AIP sampled for ``a`` (the
    null class at reset).

    Version history: v0 -- first version.
    """

    metadata = {"name": "ials_zoo_ials_parallel", "render_modes": [], "is_parallelizable": True}

    def __init__(self, core: MultiAgentIALS, null_influence: int = 0, seed: int | None = None):
        if core.n_envs != 1:
            raise BadInput("IALSParallelEnv needs one copy per agent")
        self.core = core
        self.possible_agents = list(core.agents)
        self.agents = []
        ls = core.ls
        self.observation_spaces = dict.fromkeys(self.possible_agents, ls.observation_space)
        self.action_spaces = dict.fromkeys(self.possible_agents, ls.action_space)
        width = int(np.prod(ls.observation_space.shape))
        self.state_space = spaces.Box(0.0, 1.0, (width * len(self.possible_agents),), np.float32)
        self.render_mode = None
        self._null = np.full(core.predictor.n_sources, int(null_influence), np.int64)
        self._seed = check_seed(seed)
        self._obs = None

    def observation_space(self, agent):
        return self.observation_spaces[agent]

    def action_space(self, agent):
        return self.action_spaces[agent]

    def region_spec(self, agent):
        return self.core.ls.regions[self.possible_agents.index(agent)]

    def state(self) -> np.ndarray:
        if self._obs is None:
            raise RuntimeError("state() before reset()")
        return np.asarray(self._obs, np.float32).reshape(-1)

    def _infos(self, dsets, influences):
        return {a: {INFLUENCE_KEY: influences[i], "dset": dsets["dset"][i, 0], "dset_full": dsets["full"][i, 0]}
                for i, a in enumerate(self.agents)}

    def reset(self, seed=None, options=None):
        check_reset_options(options)
        seed = check_seed(seed)
        if seed is None:
            seed = self._seed
        self._seed = None
        obs, dsets = self.core.reset(seed)
        self.agents = list(self.possible_agents)
        self._obs = obs[:, 0]
        return ({a: obs[i, 0] for i, a in enumerate(self.agents)},
                self._infos(dsets, [self._null.copy() for _ in self.agents]))

    def step(self, actions):
        if not self.agents:
            raise RuntimeError("the episode is over (or reset() was never called); call reset()")
        if not isinstance(actions, dict):
            raise BadInputType(f"actions must be a dict agent -> action, got {type(actions).__name__}")
        missing = [a for a in self.agents if a not in actions]
        extra = [a for a in actions if a not in self.agents]
        if missing or extra:
            raise BadInput(f"actions must have one entry per live agent; missing {missing}, unknown {extra}")
        acts = np.empty(len(self.agents), np.int64)
        n = int(self.action_spaces[self.agents[0]].n)
        for i, a in enumerate(self.agents):
            v = actions[a]
            if isinstance(v, np.ndarray) and v.shape == ():
                v = v[()]
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or not 0 <= v < n:
                raise BadInput(f"action of {a!r} must be an int in 0..{n - 1}, got {actions[a]!r}")
            acts[i] = v
        obs, rewards, dsets, u, done = self.core.step(acts[:, None])
        agents = self.agents
        self._obs = obs[:, 0]
        out = ({a: obs[i, 0] for i, a in enumerate(agents)}, {a: float(rewards[i, 0]) for i, a in enumerate(agents)},
               dict.fromkeys(agents, False), dict.fromkeys(agents, bool(done)), self._infos(dsets, u[:, 0]))
        if done:
            self.agents = []
        return out

    def close(self):
        self.core.close()


def make_multi_agent_ials(env_id: str, agents=None, n_envs: int = 1, predictor="trained", dset_kind: str | None = None,
                          seed: int | None = None, **options) -> MultiAgentIALS:
    """:class:`MultiAgentIALS` of ``agents`` (default: every agent) with ``n_envs`` copies each."""
    domain = get_domain(env_id).require_ials("make_multi_agent_ials")
    if isinstance(agents, str):
        raise BadInputType(f"agents must be a list of agent ids (or None for all), got the string {agents!r}; "
                        f"did you mean [{agents!r}]?")
    agents = domain.check_agents(agents, **options)
    if isinstance(predictor, dict):
        unknown = sorted(set(predictor) - set(agents))
        if unknown:
            raise BadInput(f"predictors given for {unknown}, which are not among the agents {agents}")
    preds = resolve_predictor_set(predictor, env_id, agents, dset_kind, seed, options)
    ls = domain.local_simulator(agents, n_envs=n_envs, **options)
    try:
        return MultiAgentIALS(ls, StackedPredictor(preds, n_envs))
    except BaseException:
        ls.close()
        raise


def make_ials_parallel_env(env_id: str, agents=None, predictor="trained", dset_kind: str | None = None,
                           seed: int | None = None, **options) -> IALSParallelEnv:
    """The multi-agent IALS of ``env_id`` as a PettingZoo ``ParallelEnv``.

    Args:
        env_id: domain id, e.g. ``"traffic_grid_v0"``.
        agents: the agents (default: every agent of the GS under ``options``).
        predictor: ``"trained"`` (every agent's AIP, module docstring), another predictor spec
            for every agent, a dict ``{agent: predictor}``, or a predictor-set file. (A domain
            whose agents have their own spaces builds its own: :attr:`Domain.ials_parallel_env`.)
        dset_kind: the d-set the AIPs read (``"dset"`` default).
        seed: seeds the first ``reset`` (and ``"untrained"`` weights).
        **options: domain options, as for the GS.
    """
    domain = get_domain(env_id)
    if not domain.has_ials and domain.ials_parallel_env is not None:  # agents with their own spaces
        if dset_kind not in (None, "dset"):
            raise BadInput(f"{env_id}'s multi-agent IALS reads the 'dset' d-set only, not {dset_kind!r}")
        return domain.ials_parallel_env(agents=agents, predictor=predictor, seed=seed, **options)
    domain.require_ials("make_ials_parallel_env")
    for gs_only in ("learners", "scripted_learners", "render_mode"):
        if gs_only in options:
            raise BadInput(f"{gs_only!r} is a GS option; the multi-agent IALS has no scripted agents and no renderer")
    core = make_multi_agent_ials(env_id, agents, 1, predictor, dset_kind, seed, **options)
    return IALSParallelEnv(core, domain.null_influence, seed)


__all__ = ["IALSParallelEnv", "MultiAgentIALS", "make_ials_parallel_env", "make_multi_agent_ials",
           "resolve_predictor_set", "shipped_set_path", "trained_predictor_set"]
