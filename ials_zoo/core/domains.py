"""The domain contract and registry: everything generic code knows about a domain.

A *domain* (a networked system: the warehouse, the traffic grid, your own) is one folder. Its
module ``domain.py`` defines ``DOMAIN = Domain(...)``: the global simulator (GS), the local
simulator (LS), the regions, and the few facts generic code needs (data collection, the IALS
factory, the baselines, the evaluator, the benchmark, the study). Generic code never names a
domain; it asks the :class:`Domain`.

Where domains come from (:func:`domain_ids`, in this order):

1. the package's own folders ``ials_zoo/<name>/domain.py``;
2. the Python entry point group ``ials_zoo.domains`` of any installed distribution
   (``[project.entry-points."ials_zoo.domains"] mydomain_v0 = "mypkg.domain:DOMAIN"``);
3. :func:`register_domain` at run time (e.g. a domain that lives in a test folder).

A registered domain gets the Gymnasium id ``ials_zoo/IALS-<env_id>`` of its IALS too.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import os
import pkgutil
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from gymnasium import spaces

from ials_zoo.core.gym_ids import register_ials
from ials_zoo.core.local import LocalSimulator
from ials_zoo.core.region import RegionSpec
from ials_zoo.errors import BadInput, BadInputType

ENTRY_POINT_GROUP = "ials_zoo.domains"


@dataclass(frozen=True)
class StudySettings:
    """How ``ials-zoo reproduce`` runs a domain (defaults; the command line overrides them).

    Attributes:
        budget: PPO environment steps per single-agent training run.
        ppo_steps_per_second: rough ``ppo_single`` throughput on the ``"gs"`` and on an
            ``"ials"`` simulator, only used to start the longest runs first.
        memory_variant: GS options of the domain's memory variant (paper §5.4), or None when
            the domain has none; the memory experiment runs on domains that have one.
        lifetime_probes: ``(gs_probe, ls_probe)``: ``gs_probe(env, agent)`` and
            ``ls_probe(local_simulator)`` return the ages of the items in a region (0: no
            item), for the memory experiment's item-lifetime histograms; None without items.
        multi_agent_budget: PPO steps *per agent* of a multi-agent (DIALS / IPPO) run.
        multi_agent_steps_per_second: agent-steps per second of training of a multi-agent
            run with every agent learning, on the GS (IPPO) and on IALS (DIALS, AIP time
            included), as measured by the study on 2 cores; only for the duration estimate
            a run prints first.
    """

    budget: int = 500_000
    ppo_steps_per_second: dict = field(default_factory=lambda: {"gs": 1000.0, "ials": 5000.0})
    memory_variant: dict | None = None
    lifetime_probes: tuple | None = None
    multi_agent_budget: int = 200_000
    multi_agent_steps_per_second: dict = field(default_factory=lambda: {"gs": 10_000.0, "ials": 10_000.0})


@dataclass(frozen=True)
class DIALSSettings:
    """The multi-agent (DIALS) settings of a domain (SPEC §6).

    Attributes:
        aip_arch, aip_hidden, aip_lr, aip_epochs: the AIPs retrained by DIALS.
        aip_batch: minibatch of the AIP training (episodes for a GRU, samples for an MLP).
        copies: IALS copies per agent (the default ``--n-envs``; the PPO rollout per copy is
            the samples per update divided by this).
        collect_steps: GS steps per data collection (all regions at once).
        refresh: default steps per agent between AIP refreshes (0 = train once, at the start).
        frame_stack: observations a multi-agent (IPPO, DIALS) policy reads by default (None:
            the domain's ``frame_stack``); chosen from the PPO ablation.
        aip_autoregressive: DIALS's AIPs also read their previous influence ``u_{t-1}``
            (:mod:`ials_zoo.influence.base`) by default.
        aip_autoregressive_lr: the learning rate of autoregressive AIPs (at ``aip_lr`` for
            ``aip_epochs`` the dependence on ``u_{t-1}`` is barely learned from one collection).
    """

    aip_arch: str = "mlp"
    aip_hidden: int = 64
    aip_lr: float = 1e-3
    aip_epochs: int = 10
    aip_batch: int = 256
    copies: int = 8
    collect_steps: int = 10_000
    refresh: int = 0
    frame_stack: int | None = None
    aip_autoregressive: bool = False
    aip_autoregressive_lr: float = 1e-2

    def lr_for(self, autoregressive: bool) -> float:
        """The AIP learning rate of a memoryless or an autoregressive AIP."""
        return self.aip_autoregressive_lr if autoregressive else self.aip_lr


@dataclass(frozen=True)
class Domain:
    """What a domain provides to the rest of the zoo.

    Attributes:
        env_id: versioned id, e.g. ``"warehouse_v0"``.
        parallel_env: ``parallel_env(**options) -> pettingzoo.ParallelEnv`` (the GS). Its
            ``possible_agents`` are the ``learners`` option (default: every agent); every
            other agent is scripted. It reports the region data of
            :mod:`ials_zoo.core.region` in its infos and has ``region_spec(agent)``.
        local_simulator: ``local_simulator(agent, n_envs=1, **options) -> LocalSimulator``;
            accepts (and ignores) the GS-only options.
        region_spec: ``region_spec(agent, **options) -> RegionSpec`` without building a GS.
        possible_agents: ``possible_agents(**options) -> list[str]``: every agent id of the
            GS under these options.
        observation_space, action_space: every agent's spaces (the same for all agents).
        default_agents: the agents the paper trained (their AIPs ship with the package).
        default_predictor: ``"gru"`` or ``"mlp"``, the AIP architecture of the paper.
        episode_length: default episode length (steps; every episode ends by truncation).
        frame_stack: observations the paper's policy reads (1 = current only).
        agent_options: the GS options that change the set of agents (e.g. a grid size):
            :meth:`check_agent` passes only these to ``possible_agents``.
        gs_options: every GS option that changes what an episode is (the evaluation
            protocol's ``options`` may hold these and nothing else; rendering and backends
            are not options of a result).
        one_simulation_per_process: each GS/LS holds a process-wide resource (libsumo: one
            simulation per process), so vectorised training puts each in its own process.
        null_influence: the "nothing comes in" class of the influence sources (F-IALS
            ``fixed:P`` puts probability ``1 - P`` on it).
        untrained_probs: per source, the class probabilities of the ``"uniform"`` AIP
            (SPEC §3), or None for uniform over classes.
        scaling: ``(option, sizes)`` for ``ials-zoo bench --scaling`` (the system grown
            through one GS option), or None.
        legend: ``(label, (r, g, b))`` pairs explaining the colours of the GS's
            ``rgb_array`` frames (shown on demo GIFs).
        episode_summary: ``episode_summary(env) -> dict[str, str]``: a few figures of the
            episode just run on ``env`` (a GS), for ``ials-zoo demo``.
        replay_agreement: the share of observation entries on which the LS, fed the GS's own
            actions and influence sources from the same start, must agree with the GS
            (1.0 only where the LS is exact without the GS's other random draws).
        study: :class:`StudySettings` of ``ials-zoo reproduce``.
        dials: :class:`DIALSSettings` of multi-agent training.
        tools: extra ``ials-zoo`` subcommands of this domain: ``{name: (module, help)}``,
            each module with ``configure(parser)`` and ``run(args)``.
        metrics: the physical metrics of an episode, ``{name: "lower" | "higher"}`` (which
            way is better); the GS then has ``enable_metrics()`` (record from the next
            reset on) and ``episode_metrics() -> {name: float}`` for the episode just run.
        description: one line for listings.
    """

    env_id: str
    parallel_env: Callable
    local_simulator: Callable[..., LocalSimulator]
    region_spec: Callable[..., RegionSpec]
    possible_agents: Callable[..., list]
    observation_space: spaces.Space
    action_space: spaces.Space
    default_agents: tuple[str, ...]
    default_predictor: str
    episode_length: int
    frame_stack: int = 1
    agent_options: tuple[str, ...] = ()
    gs_options: tuple[str, ...] = ()
    one_simulation_per_process: bool = False
    null_influence: int = 0
    untrained_probs: tuple | None = None
    scaling: tuple | None = None
    legend: tuple = ()
    episode_summary: Callable | None = None
    replay_agreement: float = 0.9
    study: StudySettings = field(default_factory=StudySettings)
    dials: DIALSSettings = field(default_factory=DIALSSettings)
    tools: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    description: str = ""

    def __post_init__(self):
        if self.default_predictor not in ("gru", "mlp"):
            raise BadInput(f"{self.env_id}: default_predictor must be 'gru' or 'mlp'")
        if not self.default_agents:
            raise BadInput(f"{self.env_id}: default_agents must name at least one agent")
        bad = {k: v for k, v in self.metrics.items() if v not in ("lower", "higher")}
        if bad:
            raise BadInput(f"{self.env_id}: metrics must map names to 'lower' or 'higher' (better), got {bad}")

    def agents(self, **options) -> list[str]:
        """Every agent id under ``options`` (only :attr:`agent_options` are looked at)."""
        return list(self.possible_agents(**{k: v for k, v in options.items() if k in self.agent_options}))

    def check_agent(self, agent, **options) -> str:
        """``agent`` if it is an agent of this domain under ``options``, else a ValueError
        naming the valid ids."""
        agents = self.agents(**options)
        if not isinstance(agent, str) or agent not in agents:
            shown = ", ".join(agents[:6]) + (f", ... ({len(agents)} in all)" if len(agents) > 6 else "")
            raise BadInput(f"unknown agent {agent!r} for {self.env_id}; expected one of: {shown}")
        return agent

    def check_agents(self, agents, **options) -> list[str]:
        """A list of distinct agents (None: every agent), each checked."""
        if agents is None:
            return self.agents(**options)
        if isinstance(agents, str):
            agents = [a for a in agents.split(",") if a.strip()]
        out = [self.check_agent(a.strip() if isinstance(a, str) else a, **options) for a in agents]
        if not out:
            raise BadInput(f"agents must name at least one agent of {self.env_id}")
        dup = sorted({a for a in out if out.count(a) > 1})
        if dup:
            raise BadInput(f"agents repeat: {dup}")
        return out

    @property
    def n_actions(self) -> int:
        """Number of actions of a ``Discrete`` action space."""
        return int(self.action_space.n)


# ----------------------------------------------------------------------------- the registry

_lock = threading.RLock()
_registered: dict[str, Domain] = {}  # run-time registrations
_discovered: dict[str, Callable[[], Domain]] | None = None  # env_id -> loader (built-ins, entry points)
_loaded: dict[str, Domain] = {}


def _builtin_loaders() -> dict[str, Callable[[], Domain]]:
    """Every ``ials_zoo/<package>/domain.py`` (imported: the id lives in its ``DOMAIN``)."""
    package_dir = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # ials_zoo/
    out = {}
    for info in pkgutil.iter_modules([package_dir]):
        if not (info.ispkg and os.path.isfile(os.path.join(package_dir, info.name, "domain.py"))):
            continue
        domain = importlib.import_module(f"ials_zoo.{info.name}.domain").DOMAIN
        out[domain.env_id] = (lambda d=domain: d)
    return out


def _entry_point_loaders() -> dict[str, Callable[[], Domain]]:
    out = {}
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        def load(ep=ep):
            obj = ep.load()
            domain = getattr(obj, "DOMAIN", obj)
            if not isinstance(domain, Domain):
                raise BadInputType(f"entry point {ep.name} = {ep.value!r} is not an ials_zoo Domain")
            if domain.env_id != ep.name:
                raise BadInput(f"entry point {ep.name!r} loads domain {domain.env_id!r}")
            return domain

        out.setdefault(ep.name, load)
    return out


def _loaders() -> dict[str, Callable[[], Domain]]:
    global _discovered
    with _lock:
        if _discovered is None:
            found = _builtin_loaders()
            for env_id, load in _entry_point_loaders().items():
                found.setdefault(env_id, load)
            _discovered = found
        return _discovered


def domain_ids() -> list[str]:
    """The ids of every available domain (built-in, entry points, registered)."""
    with _lock:
        return list(_loaders()) + [d for d in _registered if d not in _loaders()]


def get_domain(env_id: str) -> Domain:
    """The domain ``env_id``; a ValueError naming the available ones for an unknown id."""
    with _lock:
        if env_id in _registered:
            return _registered[env_id]
        if env_id in _loaded:
            return _loaded[env_id]
        load = _loaders().get(env_id) if isinstance(env_id, str) else None
        if load is None:
            raise BadInput(f"unknown domain {env_id!r}; available: {', '.join(domain_ids())}")
        domain = _loaded[env_id] = load()
        return domain


def register_domain(domain: Domain, replace: bool = False) -> Domain:
    """Make ``domain`` available under its ``env_id`` (and ``ials_zoo/IALS-<env_id>`` in
    Gymnasium). An id already taken is refused unless ``replace``."""
    if not isinstance(domain, Domain):
        raise BadInputType(f"register_domain needs an ials_zoo.core.Domain, got {type(domain).__name__}")
    with _lock:
        taken = domain.env_id in _registered or domain.env_id in _loaders()
        if taken and not replace:
            raise BadInput(f"a domain {domain.env_id!r} is already registered; pass replace=True")
        _registered[domain.env_id] = domain
    register_ials(domain.env_id)
    return domain


def unregister_domain(env_id: str) -> None:
    """Remove a domain added by :func:`register_domain` (built-ins stay)."""
    with _lock:
        _registered.pop(env_id, None)


def default_domain() -> str:
    """The domain command-line tools use when none is named (the first available)."""
    return domain_ids()[0]


def domain_of_agent(agent: str, **options) -> str:
    """The one domain that has an agent called ``agent`` (under default options)."""
    owners = [d for d in domain_ids() if agent in get_domain(d).agents(**options)]
    if len(owners) != 1:
        why = "no domain has" if not owners else f"several domains ({', '.join(owners)}) have"
        raise BadInput(f"{why} an agent {agent!r}; name the domain too")
    return owners[0]


__all__ = [
    "DIALSSettings",
    "Domain",
    "ENTRY_POINT_GROUP",
    "StudySettings",
    "default_domain",
    "domain_ids",
    "domain_of_agent",
    "get_domain",
    "register_domain",
    "unregister_domain",
]
