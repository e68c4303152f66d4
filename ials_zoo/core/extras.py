"""What one subsystem alone needs of a domain: the settings it reads from ``Domain.extras``.

The :class:`~ials_zoo.core.domains.Domain` contract is what every part of the zoo needs (the
environments, spaces, agents, regions and local simulator). What only one subsystem reads is
kept in ``Domain.extras``, under the subsystem's key, and read through its accessor here; a
domain that gives none gets the subsystem's defaults (the toy domain of the tests gives only
the core):

* ``"study"``: :class:`StudySettings` (``ials-zoo reproduce``, the duration estimates);
* ``"dials"``: :class:`DIALSSettings` (multi-agent training, IALS sets, fidelity);
* ``"viewer"``: :class:`ViewerSettings` (``ials-zoo demo``: the GIF legend, an episode's summary);
* ``"bench"``: :class:`BenchSettings` (``ials-zoo bench --scaling``);
* ``"tools"``: extra ``ials-zoo`` subcommands, ``{name: (module, help)}``, each module with
  ``configure(parser)`` and ``run(args)``;
* ``"learners"``: ``{algorithm: LearnerOptions}``, the GS options a learner needs here (MPLight's
  pressure observation and reward: :class:`LearnerOptions`).

The accessors take a :class:`Domain` or a domain id.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from ials_zoo.core.domains import Domain, get_domain
from ials_zoo.errors import BadInput

LR_SCHEDULES = ("linear", "constant")  # how an AIP's learning rate moves over its training


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
        gs_step_seconds: ``gs_step_seconds(**options) -> float | None``, the wall-clock of
            one GS step with every agent acting (no learning) under GS ``options``, where the
            domain knows it better than ``multi_agent_steps_per_second`` (a GS whose cost
            depends on its network more than on its agents); for the estimate an evaluation
            or a GS collection prints first.
        joint_step_seconds: ``joint_step_seconds(simulator, **options) -> float``, seconds of
            training per step of a multi-agent run counted once for all agents (``simulator``
            ``"gs"`` or ``"ials"``, ``options`` the run's), for a domain whose cost per step is
            its map's more than its agents' (a real network: 8 lights or 21 of one map take about
            the same time per step, two maps do not); when given, the opening estimate of a
            multi-agent run uses it rather than ``multi_agent_steps_per_second``.
    """

    budget: int = 500_000
    ppo_steps_per_second: dict = field(default_factory=lambda: {"gs": 1000.0, "ials": 5000.0})
    memory_variant: dict | None = None
    lifetime_probes: tuple | None = None
    multi_agent_budget: int = 200_000
    multi_agent_steps_per_second: dict = field(default_factory=lambda: {"gs": 10_000.0, "ials": 10_000.0})
    gs_step_seconds: Callable[..., float | None] | None = None
    joint_step_seconds: Callable[..., float] | None = None


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
        frame_stack: observations a learned policy (IPPO, DIALS, ``ppo_single``) reads by
            default (None: the domain's ``frame_stack``); chosen from the PPO ablation.
        ppo_samples_per_update, ppo_batch_size: the PPO update of every learner (IPPO, DIALS,
            ``ppo_single``) by default: samples of each agent per update (split over its
            copies) and minibatch; chosen from the PPO ablation.
        aip_autoregressive: DIALS's AIPs also read their previous influence ``u_{t-1}``
            (:mod:`ials_zoo.influence.base`) by default.
        aip_autoregressive_lr: the learning rate of autoregressive AIPs (at ``aip_lr`` for
            ``aip_epochs`` the dependence on ``u_{t-1}`` is barely learned from one collection).
        aip_lr_schedule: how DIALS's AIP learning rate moves over a training
            (:data:`ials_zoo.influence.train.LR_SCHEDULES`): ``"constant"``, the setting of the
            DIALS studies in ``leaderboard/writeup.md`` (at its few epochs a decaying rate would
            halve the training).
        fidelity_aip_lr, fidelity_aip_epochs, fidelity_aip_lr_schedule: the on-policy AIPs of
            ``ials-zoo fidelity`` (:mod:`ials_zoo.influence.fidelity`), trained from scratch until
            the influence they sample over whole trajectories matches the GS's; DIALS's own AIP
            training above is a cheaper budget that stops earlier (None: DIALS's settings). The
            rate decays linearly to zero by default: a constant rate leaves rare classes
            miscalibrated (:func:`ials_zoo.influence.train._scheduler`).
        fidelity_aip_influence_lags: how many past steps of their own influence the
            autoregressive on-policy AIPs read (1: ``u_{t-1}``). Traffic reads 3: a neighbouring
            light releases its cars in platoons, 2-3 steps apart, and an AIP that does not see
            them coming makes arrivals too smooth, which flatters the light (``docs/fidelity.md``).
        fidelity_collect_steps: GS steps of each joint policy's AIP data in ``ials-zoo fidelity``
            (None: ``collect_steps``).
        aip_clock_horizon: H > 0: DIALS's own AIPs read the time since the episode's start,
            ``min(t, H) / H``, as ``fidelity_aip_clock_horizon`` below (0: they do not).
        fidelity_aip_clock_horizon: H > 0: the on-policy AIPs also read the time since the
            episode's start, ``min(t, H) / H`` (0: they do not). Traffic reads 100: its grid
            starts empty, and an AIP without a clock cannot tell the first steps of an empty
            lane from later ones, so it brings the first cars too early.
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
    ppo_samples_per_update: int = 512
    ppo_batch_size: int = 128
    aip_autoregressive: bool = False
    aip_autoregressive_lr: float = 1e-2
    aip_lr_schedule: str = "constant"
    aip_clock_horizon: int = 0
    fidelity_aip_lr: float | None = None
    fidelity_aip_epochs: int | None = None
    fidelity_aip_lr_schedule: str | None = "linear"
    fidelity_aip_influence_lags: int = 1
    fidelity_collect_steps: int | None = None
    fidelity_aip_clock_horizon: int = 0

    def __post_init__(self):
        for name in ("aip_clock_horizon", "fidelity_aip_clock_horizon"):
            clock = getattr(self, name)
            if isinstance(clock, bool) or not isinstance(clock, int) or clock < 0:
                raise BadInput(f"DIALSSettings.{name} must be an int >= 0, got {clock!r}")
        lags = self.fidelity_aip_influence_lags
        if isinstance(lags, bool) or not isinstance(lags, int) or lags < 1:
            raise BadInput(f"DIALSSettings.fidelity_aip_influence_lags must be an int >= 1, got {lags!r}")
        steps = self.fidelity_collect_steps
        if steps is not None and (isinstance(steps, bool) or not isinstance(steps, int) or steps < 1):
            raise BadInput(f"DIALSSettings.fidelity_collect_steps must be an int >= 1 or None, got {steps!r}")
        for name in ("aip_lr_schedule", "fidelity_aip_lr_schedule"):
            value = getattr(self, name)
            if value not in LR_SCHEDULES and not (value is None and name.startswith("fidelity")):
                raise BadInput(f"DIALSSettings.{name} must be one of {list(LR_SCHEDULES)}, got {value!r}")

    def lr_for(self, autoregressive: bool) -> float:
        """The AIP learning rate of a memoryless or an autoregressive AIP."""
        return self.aip_autoregressive_lr if autoregressive else self.aip_lr


@dataclass(frozen=True)
class ViewerSettings:
    """How ``ials-zoo demo`` shows a domain.

    Attributes:
        legend: ``(label, (r, g, b))`` pairs explaining the colours of the GS's ``rgb_array``
            frames (shown on demo GIFs).
        episode_summary: ``episode_summary(env) -> dict[str, str]``: a few figures of the
            episode just run on ``env`` (a GS), or None.
    """

    legend: tuple = ()
    episode_summary: Callable | None = None


@dataclass(frozen=True)
class BenchSettings:
    """How ``ials-zoo bench`` measures a domain.

    Attributes:
        scaling: ``(option, sizes)`` for ``--scaling`` (the system grown through one GS
            option), or None.
        gs_runner: see below.
    """

    scaling: tuple | None = None
    gs_runner: Callable | None = None
    """For a domain without an IALS: ``gs_runner(nets, repeats) -> rows`` measures (and prints)
    its GS instead, ``nets`` the ``--net`` names (None: the domain's defaults)."""
    nets: tuple[str, ...] = ()
    """The names ``--net`` takes (checked before any work; empty: the runner checks)."""


@dataclass(frozen=True)
class LearnerOptions:
    """The GS options a learner of the zoo trains with on a domain (MPLight's pressure MDP).

    Attributes:
        observe: what its agents read, among the domain's ``policy_options``: kept with its
            policy, so that an evaluation shows the policy what it learnt from.
        train: what it learns from in training only (a reward of its own): every policy is
            scored on the domain's own reward.
    """

    observe: dict = field(default_factory=dict)
    train: dict = field(default_factory=dict)


def learner_options_of(domain, algorithm: str) -> LearnerOptions | None:
    """The GS options ``algorithm`` needs on the domain, or None where the domain has none for it."""
    return dict(_extra(domain, "learners", {})).get(algorithm)


def _extra(domain, kind: str, default):
    domain = domain if isinstance(domain, Domain) else get_domain(domain)
    return domain.extras.get(kind, default)


def study_of(domain) -> StudySettings:
    """The domain's :class:`StudySettings` (defaults when it gives none)."""
    return _extra(domain, "study", _DEFAULT_STUDY)


def dials_of(domain) -> DIALSSettings:
    """The domain's :class:`DIALSSettings` (defaults when it gives none)."""
    return _extra(domain, "dials", _DEFAULT_DIALS)


def viewer_of(domain) -> ViewerSettings:
    """The domain's :class:`ViewerSettings` (no legend, no summary when it gives none)."""
    return _extra(domain, "viewer", _DEFAULT_VIEWER)


def bench_of(domain) -> BenchSettings:
    """The domain's :class:`BenchSettings` (no scaling when it gives none)."""
    return _extra(domain, "bench", _DEFAULT_BENCH)


def tools_of(domain) -> dict:
    """The domain's extra ``ials-zoo`` subcommands (none when it gives none)."""
    return dict(_extra(domain, "tools", {}))


_DEFAULT_STUDY, _DEFAULT_DIALS = StudySettings(), DIALSSettings()
_DEFAULT_VIEWER, _DEFAULT_BENCH = ViewerSettings(), BenchSettings()

__all__ = ["BenchSettings", "DIALSSettings", "LearnerOptions", "StudySettings", "ViewerSettings", "bench_of", "dials_of",
           "learner_options_of", "study_of", "tools_of", "viewer_of"]
