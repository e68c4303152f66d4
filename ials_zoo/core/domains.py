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
import pickle
import pkgutil
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

import cloudpickle
from gymnasium import spaces

from ials_zoo.core.gym_ids import register_ials
from ials_zoo.core.local import LocalSimulator
from ials_zoo.core.region import RegionSpec
from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.runtime.processes import add_worker_context

ENTRY_POINT_GROUP = "ials_zoo.domains"
# the subsystems that keep per-domain settings in Domain.extras (ials_zoo.core.extras)
EXTRA_KINDS = ("study", "dials", "viewer", "bench", "tools", "learners")


@dataclass(frozen=True)
class Rule:
    """A rule-based controller of every agent: a reference on the multi-agent track (the
    evaluator's ``rule:NAME`` policy; :attr:`Domain.rules`).

    Attributes:
        description: one line for listings and the board.
        make: ``make(env) -> act``, where ``act(env) -> {agent: action}`` reads the GS it drives
            (its queues, say); None: the GS's own controller drives the agents under
            :attr:`env_options` and their actions are ignored.
        env_options: GS options the rule runs under (e.g. ``{"scripted_learners": "actuated"}``);
            they are the rule's, not the protocol's: its entry stays on its network's track.
    """

    description: str
    make: Callable | None = None
    env_options: dict = field(default_factory=dict)

# the local simulators a domain with a batched IALS (``Domain.ials_batched_env``) lets a user
# pick with the IALS option ``local``: SUMO regions (the default) or numpy arrays
LOCAL_SIMULATORS = ("sumo", "arrays")


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
            accepts (and ignores) the GS-only options. None for a domain that has a GS only
            (no IALS yet: :attr:`has_ials` is False, and the IALS tools refuse it by name). A
            domain whose agents have their own spaces (no :attr:`observation_space`) has the
            single-agent IALS only (``make_ials``, ``train-aip``: :attr:`has_local_simulator`).
        region_spec: ``region_spec(agent, **options) -> RegionSpec`` without building a GS
            (None without a local simulator).
        possible_agents: ``possible_agents(**options) -> list[str]``: every agent id of the
            GS under these options.
        observation_space, action_space: every agent's spaces (the same for all agents); None
            where agents have their own (the GS's ``observation_space(agent)`` says).
        default_agents: the agents the paper trained (their AIPs ship with the package).
        default_predictor: ``"gru"`` or ``"mlp"``, the AIP architecture of the paper (None
            without a local simulator).
        episode_length: default episode length (steps; every episode ends by truncation).
        frame_stack: observations the paper's policy reads (1 = current only).
        agent_options: the GS options that change the set of agents (e.g. a grid size):
            :meth:`check_agent` passes only these to ``possible_agents``.
        gs_options: every GS option that changes what an episode is (the evaluation
            protocol's ``options`` may hold these and nothing else; rendering and backends
            are not options of a result).
        file_options: GS options that name a user's own files (a network of their own, say):
            training and evaluation take them, with their paths made absolute
            (:meth:`with_absolute_files`), and a board entry never does (the board keeps the
            domain's own scenarios, and a result never makes it read a file).
        one_simulation_per_process: each GS/LS holds a process-wide resource (libsumo: one
            simulation per process), so vectorised training puts each in its own process.
        null_influence: the "nothing comes in" class of the influence sources (F-IALS
            ``fixed:P`` puts probability ``1 - P`` on it).
        untrained_probs: per source, the class probabilities of the ``"uniform"`` AIP
            (SPEC §3), or None for uniform over classes.
        replay_agreement: the share of observation entries on which the LS, fed the GS's own
            actions and influence sources from the same start, must agree with the GS
            (1.0 only where the LS is exact without the GS's other random draws).
        ials_parallel_env: a domain whose agents have their own spaces may give its own
            multi-agent IALS, ``ials_parallel_env(agents=None, predictor=..., seed=None,
            **options) -> pettingzoo.ParallelEnv`` (``make_ials_parallel_env`` returns it).
        ials_batched_env: ``ials_batched_env(agents, predictor, seeds, **options)``: copies of
            that multi-agent IALS stepped as one batch (``reset(seeds)``, ``step(actions [A,
            copies])``, ``set_predictors``, ``close``, ``width``), or None where the options ask
            for one simulation per copy; DIALS's copies use it where it gives one.
        collect_options: GS options the influence collector adds to the GS it runs (a GS that
            reports its region data only when asked, because watching regions costs).
        metrics: the physical metrics of an episode, ``{name: "lower" | "higher"}`` (which
            way is better); the GS then has ``enable_metrics()`` (record from the next
            reset on) and ``episode_metrics() -> {name: float}`` for the episode just run.
        metric_ranges: ``{name: (low, high)}``, the values a metric can take (an episode's
            mean); a metric not named is a count, a time or a length: ``[0, inf)``.
            Results are checked against them (:meth:`metric_range`).
        score_metric: the metric that ranks this domain's entries on the board (e.g. RESCO's
            ``"delay"``, which way is better as in :attr:`metrics`), or None: the score (the
            mean return) ranks them.
        track_options: GS options that name a board track of their own (e.g. ``("net",)``:
            one track per network); other options make an entry a protocol variant.
        episode_steps: the steps of an episode under GS options (a network's hour of
            decisions, say), or None: ``max_cycles`` if given, else :attr:`episode_length`
            (:meth:`steps_of_episode`; what an evaluation's cost is estimated from).
        policy_options: GS options that change only what the agents observe, never the
            episode nor its rewards (e.g. ``("observation",)``): a policy keeps the ones it was
            trained with, and its result stays on the official protocol.
        gs_only: ``{option: values}`` that the GS takes and a local simulator cannot (an
            observation that reads other agents, say): :meth:`check_ials_options` refuses them
            before an IALS run starts.
        reward_option, rewards: the GS option that picks the agents' reward and the rewards
            it takes (the first is the one that scores them): a learner may learn from another
            (``train idqn --train-reward``) and is still scored on the protocol's; None: one reward.
        published: ``published(**track_options) -> (note, [(who, figure), ...])``: others'
            published figures for a track (a paper's table, say), shown beside its board table
            as a reference, never ranked nor re-measured; None: none.
        rules: ``{name: Rule}``, the domain's rule-based controllers of every agent (the
            multi-agent track's references beside ``random``; :class:`Rule`).
        description: one line for listings.
        extras: what one subsystem alone reads, keyed by it (:mod:`ials_zoo.core.extras`:
            ``"study"``, ``"dials"``, ``"viewer"``, ``"bench"``, ``"tools"``); a domain
            without them gets each subsystem's defaults.
    """

    env_id: str
    parallel_env: Callable
    possible_agents: Callable[..., list]
    default_agents: tuple[str, ...]
    episode_length: int
    local_simulator: Callable[..., LocalSimulator] | None = None
    region_spec: Callable[..., RegionSpec] | None = None
    observation_space: spaces.Space | None = None
    action_space: spaces.Space | None = None
    default_predictor: str | None = None
    frame_stack: int = 1
    agent_options: tuple[str, ...] = ()
    gs_options: tuple[str, ...] = ()
    file_options: tuple[str, ...] = ()
    one_simulation_per_process: bool = False
    null_influence: int = 0
    untrained_probs: tuple | None = None
    replay_agreement: float = 0.9
    ials_parallel_env: Callable | None = None
    ials_batched_env: Callable | None = None
    collect_options: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    metric_ranges: dict = field(default_factory=dict)
    score_metric: str | None = None
    track_options: tuple[str, ...] = ()
    episode_steps: Callable[..., int] | None = None
    rules: dict = field(default_factory=dict)
    reward_option: str | None = None
    rewards: tuple[str, ...] = ()
    published: Callable | None = None
    policy_options: tuple[str, ...] = ()
    gs_only: dict = field(default_factory=dict)
    description: str = ""
    extras: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.local_simulator is not None:
            missing = [k for k in ("region_spec",) if getattr(self, k) is None]
            if (self.observation_space is None) != (self.action_space is None):
                missing += ["observation_space" if self.observation_space is None else "action_space"]
            if missing:
                raise BadInput(f"{self.env_id}: a domain with a local simulator needs {', '.join(missing)}")
            if self.default_predictor not in ("gru", "mlp"):
                raise BadInput(f"{self.env_id}: default_predictor must be 'gru' or 'mlp'")
        if not self.default_agents:
            raise BadInput(f"{self.env_id}: default_agents must name at least one agent")
        unknown = sorted(set(self.extras) - set(EXTRA_KINDS))
        if unknown:
            raise BadInput(f"{self.env_id}: unknown extras {unknown}; expected some of {list(EXTRA_KINDS)}")
        bad = {k: v for k, v in self.metrics.items() if v not in ("lower", "higher")}
        if bad:
            raise BadInput(f"{self.env_id}: metrics must map names to 'lower' or 'higher' (better), got {bad}")
        if self.score_metric is not None and self.score_metric not in self.metrics:
            raise BadInput(f"{self.env_id}: score_metric {self.score_metric!r} is not one of its metrics")
        bad = [k for k, v in self.rules.items() if not isinstance(v, Rule) or not str(k).isidentifier()
               or k in ("random", "scripted")]
        if bad:
            raise BadInput(f"{self.env_id}: rules must map names (identifiers, not 'random' or 'scripted') to Rule, "
                           f"got {bad}")
        if not set(self.track_options) | set(self.policy_options) <= set(self.gs_options):
            raise BadInput(f"{self.env_id}: track_options and policy_options must be GS options, got "
                           f"{list(self.track_options) + list(self.policy_options)}")

    def with_absolute_files(self, options: dict) -> dict:
        """``options`` with the paths its :attr:`file_options` name (a path, or a list of them)
        made absolute, so that a run, its recorded command and its policy work from any folder."""
        out = dict(options)
        for key in set(self.file_options) & set(out):
            value = out[key]
            if isinstance(value, str):
                out[key] = os.path.abspath(value)
            elif isinstance(value, (list, tuple)):
                out[key] = [os.path.abspath(v) if isinstance(v, str) else v for v in value]
        return out

    def metric_range(self, name: str) -> tuple[float, float]:
        """The values metric ``name`` can take (:attr:`metric_ranges`; default ``[0, inf)``)."""
        low, high = self.metric_ranges.get(name, (0.0, float("inf")))
        return float(low), float(high)

    def steps_of_episode(self, **options) -> int:
        """Steps of one episode under GS ``options`` (:attr:`episode_steps`)."""
        if self.episode_steps is not None:
            return int(self.episode_steps(**options))
        return int(options.get("max_cycles", self.episode_length))

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
    def has_ials(self) -> bool:
        """Whether the domain has a local simulator and agents that share their spaces (and so
        every IALS tool: multi-agent IALS, DIALS, fidelity, ...); a domain with a GS only has
        none yet, and one whose agents have their own spaces has the single-agent IALS alone
        (:attr:`has_local_simulator`)."""
        return self.local_simulator is not None and self.observation_space is not None

    @property
    def has_local_simulator(self) -> bool:
        """Whether one agent's IALS can be built (``make_ials``, ``train-aip``)."""
        return self.local_simulator is not None

    @property
    def has_ials_parallel_env(self) -> bool:
        """Whether every agent's IALS runs as one PettingZoo ParallelEnv
        (``make_ials_parallel_env``; what ``fidelity`` and DIALS need): agents that share their
        spaces, or agents of their own spaces with the domain's own ``ials_parallel_env``."""
        return self.has_ials or (self.has_local_simulator and self.ials_parallel_env is not None)

    def _require(self, has: str, what: str, needs: str, having: str) -> Domain:
        """This domain if its property ``has`` holds, else a BadInput saying that ``what`` needs
        ``needs`` and naming the domains that have it (``having``)."""
        if not getattr(self, has):
            others = ", ".join(d for d in domain_ids() if getattr(get_domain(d), has))
            raise BadInput(f"{what} needs {needs}, which {self.env_id} does not have yet; its GS is "
                           f"ials_zoo.{self.env_id}.parallel_env() ({having}: {others})")
        return self

    def check_ials_options(self, options: dict, what: str, flag: str = "--env-options") -> None:
        """A BadInput naming ``flag`` where ``options`` hold a value of :attr:`gs_only`: ``what``
        (a command) would fail on it only once its local simulators start."""
        for option, values in self.gs_only.items():
            if options.get(option) in values:
                raise BadInput(f"{flag}: {what} runs {self.env_id}'s local simulators, which cannot take "
                               f"{option}={options[option]!r} ({', '.join(map(repr, values))} are the GS's only)")

    def require_ials_parallel_env(self, what: str) -> Domain:
        """This domain, or a BadInput saying that ``what`` needs a multi-agent IALS it lacks."""
        return self._require("has_ials_parallel_env", what, "every agent's IALS as one ParallelEnv", "domains with one")

    def require_local_simulator(self, what: str) -> Domain:
        """This domain, or a BadInput saying that ``what`` needs a local simulator it lacks."""
        return self._require("has_local_simulator", what, "a local simulator", "domains with one")

    def require_ials(self, what: str) -> Domain:
        """This domain, or a BadInput saying that ``what`` needs a local simulator and shared
        agent spaces (saying which of the two it lacks)."""
        if self.has_local_simulator and not self.has_ials:
            others = ", ".join(d for d in domain_ids() if get_domain(d).has_ials)
            multi = (" (every agent at once: `ials-zoo train ippo|dials`)" if self.has_ials_parallel_env else "")
            raise BadInput(f"{what} needs a local simulator and shared agent spaces: {self.env_id} has the first, but "
                           f"its agents each have their own spaces. Its one-agent IALS is ials_zoo.make_ials("
                           f"{self.env_id!r}, AGENT, ...){multi}; domains whose agents share their spaces: {others}")
        return self._require("has_ials", what, "a local simulator and shared agent spaces", "domains with an IALS")

    @property
    def n_actions(self) -> int:
        """Number of actions of a ``Discrete`` action space."""
        if self.action_space is None:
            raise BadInput(f"{self.env_id}: every agent has its own action space; ask the env's action_space(agent)")
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


def ials_domain_ids() -> list[str]:
    """The ids of the domains with a local simulator (:attr:`Domain.has_ials`)."""
    return [d for d in domain_ids() if get_domain(d).has_ials]


def dials_domain_ids() -> list[str]:
    """The ids of the domains DIALS trains on (:attr:`Domain.has_ials_parallel_env`): those of
    :func:`ials_domain_ids` and those whose agents have their own spaces but one IALS ParallelEnv
    (sumo_net_v0)."""
    return [d for d in domain_ids() if get_domain(d).has_ials_parallel_env]


def get_domain(env_id: str | Domain) -> Domain:
    """The domain ``env_id``; a ValueError naming the available ones for an unknown id. A
    :class:`Domain` is returned as it is: a caller that resolved the id once passes the object
    down, and a function that takes either needs no second lookup."""
    if isinstance(env_id, Domain):
        return env_id
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
    if domain.has_ials:
        register_ials(domain.env_id)
    return domain


def _install_domains(payload: bytes) -> None:
    """In a worker process: register the domains its parent registered at run time."""
    for domain in pickle.loads(payload):  # from our own parent, over our own pipe
        register_domain(domain, replace=True)


def _worker_context():
    # a worker (ials_zoo.runtime.processes.Worker) starts a fresh interpreter: the domains registered
    # here at run time go with it (their functions must live in modules it can import)
    with _lock:
        domains = list(_registered.values())
    # by value (cloudpickle, a gymnasium dependency): a domain's functions may be lambdas
    return (_install_domains, cloudpickle.dumps(domains)) if domains else None


add_worker_context(_worker_context)


def unregister_domain(env_id: str) -> None:
    """Remove a domain added by :func:`register_domain` (built-ins stay)."""
    with _lock:
        _registered.pop(env_id, None)


def default_domain() -> str:
    """The domain command-line tools use when none is named (the first with an IALS)."""
    return ials_domain_ids()[0]


def domain_of_agent(agent: str, **options) -> str:
    """The one domain that has an agent called ``agent`` (under default options)."""
    owners = [d for d in domain_ids() if agent in get_domain(d).agents(**options)]
    if len(owners) != 1:
        why = "no domain has" if not owners else f"several domains ({', '.join(owners)}) have"
        raise BadInput(f"{why} an agent {agent!r}; name the domain too")
    return owners[0]


__all__ = [
    "Domain",
    "ENTRY_POINT_GROUP",
    "default_domain",
    "dials_domain_ids",
    "domain_ids",
    "domain_of_agent",
    "get_domain",
    "ials_domain_ids",
    "register_domain",
    "Rule",
    "unregister_domain",
]
