"""Does the multi-agent IALS reproduce the GS? The influence over whole trajectories, under
several joint policies, agent by agent.

Usage::

    ials-zoo fidelity --env <domain id> [--episodes 20] [--policies random,constant,FILE.safetensors]

Every agent of the GS acts with one joint policy; the multi-agent IALS (every agent on its own
local simulator, interacting only through its AIP) runs the same joint policy. For a few
agents (the first and second of the domain's row-major list, a corner and an edge agent of a
grid, and the domain's default agent, a central one) the report gives, per episode and then
as a mean with a 95% interval over episodes, in the GS and in the IALS:

* ``active``: the share of steps at which an influence source is active (``u_t`` not the
  domain's null class: a neighbour on a shared cell, a car entering a lane);
* ``persistence``: P(u_t = u_{t-1} | u_{t-1} active): does an active source stay active (a
  neighbour that lingers, a platoon of cars)?
* ``arrivals``: how many times per episode a source becomes active or changes class (one
  lingering neighbour is one arrival in the GS; an AIP that forgets its own samples turns it
  into many);
* ``run_length``: the mean length of a source's active runs (stays);
* ``gap``: the mean number of steps between a source's successive arrivals (platoons of cars
  show as short gaps; where an arrival lasts one step, as a car entering a lane, this and
  ``persistence`` are how the temporal structure shows);
* ``return``: the agent's own episodic return.

Which AIPs: ``--predictor`` a fixed set for every joint policy (the shipped set was trained on
uniformly random agents, so it can only be right for them: a neighbour's behaviour depends on
its policy, which no d-set shows), or ``on-policy`` / ``on-policy-autoregressive``: for each
joint policy, AIPs trained on GS data of that very policy (``--collect-steps`` steps, the
domain's DIALS AIP architecture, data seeds apart from the evaluation's), what DIALS retrains
its AIPs on; the latter with autoregressive AIPs (:mod:`ials_zoo.influence.base`). They train
at the domain's ``DIALSSettings.fidelity_aip_lr`` for ``fidelity_aip_epochs``, the rate
decaying linearly to zero (``fidelity_aip_lr_schedule``: at a constant rate the last iterate
leaves rare classes miscalibrated, e.g. a lane's entry rate 30% low; :mod:`ials_zoo.influence.train`): an
autoregressive AIP must learn how long a source stays active and when it comes back, which
DIALS's cheaper training budget only partly does (``--aip-lr``/``--aip-epochs`` measure that).
Early stopping on the held-out cross-entropy does not help: it stops traffic's AIPs after 4-16
of 30 epochs, before they learn that two cars never enter a lane in consecutive steps (a rare
event, small in the loss, large over a trajectory).

A row "holds" when the 95% interval of the GS - IALS difference (Welch, over episodes)
contains 0, or when the difference is within ``--tolerance`` (relative, default 10%) of the
GS value: the tolerance comes from the sampling error, stated in the report. The interval covers
the episodes' sampling error, not the AIPs' training: ``--aip-seeds K`` trains the on-policy
AIPs K times (other GS data, other seeds) and the report counts, per row, under how many of
them it holds. Training ``k`` collects its data (and seeds its training) from
``seed + 100000 + k``, so ``--seed 0``'s second training is ``--seed 1``'s first; the
evaluation episodes differ. Joint policies:
``random`` (uniform), ``constant`` (every agent always takes action 0: lights that keep their
phase, robots that walk to a shelf and stay there, the lingering case), ``cycle:H`` (every agent
cycles through its actions, holding each for H steps: in traffic a fixed-time plan of H-decision
greens, every light starting on its first), a joint policy file
(e.g. the board's), ``scripted`` (the GS only: scripted controllers have no IALS form).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ials_zoo.core.domains import get_domain
from ials_zoo.core.extras import dials_of
from ials_zoo.core.spaces import JointSizes, joint_sizes, stack_observations
from ials_zoo.errors import BadInput
from ials_zoo.evaluation import FrameStack, load_model
from ials_zoo.influence.base import check_clock_horizon, check_influence_lags
from ials_zoo.influence.dataset import collect_all
from ials_zoo.influence.specs import parse_predictor
from ials_zoo.influence.train import LR_SCHEDULES, train_predictors

METRICS = ("active", "persistence", "arrivals", "run_length", "gap", "return")


@dataclass
class Trajectories:
    """Per episode and agent: the influence ``u`` [T, M] and the agent's return."""

    influence: dict = field(default_factory=dict)  # agent -> list of [T, M] arrays
    returns: dict = field(default_factory=dict)  # agent -> list of floats


def _joint_actions(policy, agents, sizes: JointSizes, rng, obs, stack):
    if policy == "random":  # each agent among its own actions
        return rng.integers(np.asarray(sizes.action_counts or (sizes.n_actions,) * len(agents)))
    if policy == "constant":
        return np.zeros(len(agents), np.int64)
    return policy.act_all(stack)


def run(env, agents: Sequence[str], watched: Sequence[str], policy, episodes: int, seed: int,
        sizes: JointSizes) -> Trajectories:
    """Run ``episodes`` of a ParallelEnv (GS or multi-agent IALS) with a joint ``policy``
    (``"random"``, ``"constant"`` or a :class:`~ials_zoo.evaluation.NetworkPolicy`) and record
    the ``watched`` agents' influence and returns. ``sizes``: the agents' joint sizes (their
    observations zero-padded to the longest, as a joint policy reads them)."""
    out = Trajectories({a: [] for a in watched}, {a: [] for a in watched})
    frames = FrameStack(getattr(policy, "frame_stack", 1))
    rng = np.random.default_rng(seed)
    for e in range(episodes):
        if not isinstance(policy, str):
            policy.reset(seed + e)
        obs, _ = env.reset(seed=seed + e)
        x = frames.reset(stack_observations(obs, agents, sizes.obs_size))
        us = {a: [] for a in watched}
        totals = dict.fromkeys(watched, 0.0)
        while env.agents:
            acts = _joint_actions(policy, agents, sizes, rng, obs, x)
            obs, rewards, _, _, infos = env.step({a: int(u) for a, u in zip(agents, acts)})
            for a in watched:
                us[a].append(np.asarray(infos[a]["influence"], np.int64).ravel())
                totals[a] += float(rewards[a])
            if env.agents:
                x = frames.step(stack_observations(obs, agents, sizes.obs_size))
        for a in watched:
            out.influence[a].append(np.stack(us[a]))
            out.returns[a].append(totals[a])
    return out


def episode_metrics(u: np.ndarray, null: int) -> dict:
    """The influence metrics of one episode's ``u`` [T, M] (module docstring), pooled over the
    region's sources."""
    active = u != null
    prev_active = active[:-1]
    same = (u[1:] == u[:-1]) & prev_active
    starts = active & np.vstack([np.ones((1, u.shape[1]), bool), (u[1:] != u[:-1])])
    runs = []
    for m in range(u.shape[1]):
        length = 0
        for t in range(u.shape[0]):
            if active[t, m] and (t == 0 or u[t, m] == u[t - 1, m]):
                length += 1
            elif active[t, m]:  # a new class starts a new run
                if length:
                    runs.append(length)
                length = 1
            else:
                if length:
                    runs.append(length)
                length = 0
        if length:
            runs.append(length)
    gaps = [d for m in range(u.shape[1]) for d in np.diff(np.flatnonzero(starts[:, m]))]
    return {"active": float(active.mean()),
            "persistence": float(same.sum() / prev_active.sum()) if prev_active.any() else math.nan,
            "arrivals": float(starts.sum()),
            "run_length": float(np.mean(runs)) if runs else math.nan,
            "gap": float(np.mean(gaps)) if gaps else math.nan}


def summarise(traj: Trajectories, null: int) -> dict:
    """``{agent: {metric: [value per episode]}}``."""
    out = {}
    for a, us in traj.influence.items():
        rows = [episode_metrics(u, null) for u in us]
        out[a] = {k: [r[k] for r in rows] for k in METRICS if k != "return"}
        out[a]["return"] = list(traj.returns[a])
    return out


def compare(gs: list[float], ials: list[float], tolerance: float) -> dict:
    """Means, the Welch 95% interval of the difference, and whether the row holds."""
    from scipy import stats

    a = np.asarray([x for x in gs if x == x], float)
    b = np.asarray([x for x in ials if x == x], float)
    if len(a) < 2 or len(b) < 2:
        return {"gs": float(a.mean()) if len(a) else math.nan, "ials": float(b.mean()) if len(b) else math.nan,
                "low": math.nan, "high": math.nan, "holds": None}
    diff = a.mean() - b.mean()
    va, vb = a.var(ddof=1) / len(a), b.var(ddof=1) / len(b)
    se = math.sqrt(va + vb)
    if se == 0:
        low = high = diff
    else:
        dof = (va + vb) ** 2 / ((va ** 2 / (len(a) - 1) if va else 0) + (vb ** 2 / (len(b) - 1) if vb else 0) or 1e-300)
        half = float(stats.t.ppf(0.975, max(dof, 1.0))) * se
        low, high = diff - half, diff + half
    holds = bool(low <= 0 <= high or abs(diff) <= tolerance * abs(a.mean()))
    return {"gs": float(a.mean()), "ials": float(b.mean()), "low": float(low), "high": float(high), "holds": holds}


ON_POLICY = ("on-policy", "on-policy-autoregressive")


class CyclePolicy:
    """``cycle:H``: at step ``t`` every agent takes action ``(t // H) % n`` of its ``n`` (a
    fixed-time plan); a joint policy as :func:`run` and :class:`_PolicyActor` drive one."""

    frame_stack = 1

    def __init__(self, hold: int, action_counts):
        self.hold, self.counts, self.t = int(hold), np.asarray(action_counts, np.int64), 0

    def reset(self, seed) -> None:
        self.t = 0

    def act_all(self, obs) -> np.ndarray:
        actions = (self.t // self.hold) % self.counts
        self.t += 1
        return actions


def parse_cycle(spec: str) -> int | None:
    """H of a ``cycle:H`` policy spec (an int >= 1), None for another spec; BadInput if malformed."""
    if not spec.startswith("cycle:"):
        return None
    hold = spec.partition(":")[2]
    if not hold.isdigit() or int(hold) < 1:
        raise BadInput(f"a cycle policy is cycle:H with H an int >= 1 (steps per action), got {spec!r}")
    return int(hold)


def _joint_policy(spec: str, sizes: JointSizes, n_agents: int):
    """The policy a spec names: "random", "constant", "scripted" stay names; cycle:H, a file."""
    if spec in ("random", "constant", "scripted"):
        return spec
    hold = parse_cycle(spec)
    if hold is not None:
        return CyclePolicy(hold, sizes.action_counts or (sizes.n_actions,) * n_agents)
    return load_model(spec)
DATA_SEED_OFFSET = 100_000  # the AIPs' data episodes never repeat the evaluation's


class _PolicyActor:
    """A joint policy as :func:`~ials_zoo.influence.dataset.collect_all` drives it."""

    def __init__(self, policy, agents, seed: int, width: int | None = None):
        self.policy, self.agents, self.seed, self.episode = policy, list(agents), int(seed), 0
        self.width = width  # observations zero-padded to it (agents with spaces of their own)
        self.frames = FrameStack(getattr(policy, "frame_stack", 1))
        self.name, self.x = "joint policy", None

    def reset(self):
        self.policy.reset(self.seed + self.episode)
        self.episode += 1
        self.x = None

    def joint_act(self, observations: dict) -> dict:
        obs = stack_observations(observations, self.agents, self.width)
        self.x = self.frames.reset(obs) if self.x is None else self.frames.step(obs)
        return {a: int(u) for a, u in zip(self.agents, self.policy.act_all(self.x))}


def on_policy_training(env_id: str, autoregressive: bool, lr: float | None = None,
                       epochs: int | None = None, lr_schedule: str | None = None,
                       influence_lags: int | None = None) -> tuple[float, int, str, int]:
    """The learning rate, epochs, learning-rate schedule and influence lags (0 for memoryless
    AIPs) of the on-policy AIPs: ``lr``/``epochs``/``lr_schedule``/``influence_lags`` where
    given, else the domain's ``fidelity_aip_lr`` / ``fidelity_aip_epochs`` /
    ``fidelity_aip_lr_schedule`` / ``fidelity_aip_influence_lags``, else its DIALS AIP
    training."""
    d = dials_of(env_id)
    if influence_lags is not None:
        influence_lags = check_influence_lags(influence_lags)
        if not autoregressive:
            raise BadInput("influence lags need autoregressive AIPs (--predictor on-policy-autoregressive)")
    if lr_schedule is not None and lr_schedule not in LR_SCHEDULES:
        raise BadInput(f"aip_lr_schedule must be one of {list(LR_SCHEDULES)} (or None: the domain's), "
                       f"got {lr_schedule!r}")
    if lr is not None and not (isinstance(lr, numbers.Real) and math.isfinite(lr) and lr > 0):
        raise BadInput(f"aip_lr must be a finite number > 0 (or None: the domain's), got {lr!r}")
    if epochs is not None and (isinstance(epochs, bool) or not isinstance(epochs, numbers.Integral) or epochs < 1):
        raise BadInput(f"aip_epochs must be an int >= 1 (or None: the domain's), got {epochs!r}")
    if lr is None:
        lr = d.fidelity_aip_lr if d.fidelity_aip_lr is not None else d.lr_for(autoregressive)
    if epochs is None:
        epochs = d.fidelity_aip_epochs if d.fidelity_aip_epochs is not None else d.aip_epochs
    if lr_schedule is None:
        lr_schedule = d.fidelity_aip_lr_schedule if d.fidelity_aip_lr_schedule is not None else d.aip_lr_schedule
    if influence_lags is None:
        influence_lags = d.fidelity_aip_influence_lags
    return float(lr), int(epochs), str(lr_schedule), int(influence_lags) if autoregressive else 0


def on_policy_aips(env_id: str, agents, policy, steps: int, seed: int, autoregressive: bool, options: dict,
                   lr: float | None = None, epochs: int | None = None, lr_schedule: str | None = None,
                   influence_lags: int | None = None, clock_horizon: int | None = None,
                   width: int | None = None) -> dict:
    """``{agent: AIP}`` trained on ``steps`` GS steps of the joint ``policy`` (every agent
    acting), with the domain's DIALS AIP architecture, at its ``fidelity_aip_lr``,
    ``fidelity_aip_epochs``, ``fidelity_aip_lr_schedule`` and (autoregressive)
    ``fidelity_aip_influence_lags`` (:class:`~ials_zoo.core.extras.DIALSSettings`; ``lr``,
    ``epochs``, ``lr_schedule``, ``influence_lags``: others), reading a clock of horizon
    ``clock_horizon`` (None: the domain's ``fidelity_aip_clock_horizon``)."""
    d = dials_of(env_id)
    if policy == "random":
        actor = None
    elif policy == "constant":
        actor = {a: (lambda obs: 0) for a in agents}
    else:
        actor = _PolicyActor(policy, agents, seed, width)
    lr, epochs, lr_schedule, lags = on_policy_training(env_id, autoregressive, lr, epochs, lr_schedule,
                                                       influence_lags)
    data = collect_all(env_id, agents, steps=steps, policy=actor, seed=seed, gs_options=options, progress=False)
    preds, _ = train_predictors(data, d.aip_arch, hidden=d.aip_hidden, lr=lr, epochs=epochs,
                                batch_size=d.aip_batch, seed=seed, autoregressive=autoregressive,
                                lr_schedule=lr_schedule, influence_lags=lags,
                                clock_horizon=d.fidelity_aip_clock_horizon if clock_horizon is None else clock_horizon)
    return preds


def default_watched(domain, agents: Sequence[str]) -> list[str]:
    """The first and second agents and the domain's default one (see the module docstring)."""
    picks = [*agents[:2], domain.default_agents[0]]  # a network of one light has no second
    return list(dict.fromkeys(a for a in picks if a in agents))


def _check_aips_exist(env_id: str, agents: list, predictor, options: dict) -> None:
    """A fixed AIP set that is neither shipped nor cached is refused before any GS episode (not
    after the policies' episodes ran)."""
    from ials_zoo.influence.ials import resolve_predictor
    from ials_zoo.influence.multi import resolve_predictor_set

    if not isinstance(predictor, str) or parse_predictor(predictor).kind != "trained" or \
            parse_predictor(predictor).train_if_missing:
        return
    try:  # as the domain's multi-agent IALS resolves them: its own env per light, or one set
        if get_domain(env_id).ials_parallel_env is not None:
            for agent in agents:
                resolve_predictor(predictor, env_id, agent, options=options)
        else:
            resolve_predictor_set(predictor, env_id, agents, options=options)
    except FileNotFoundError as exc:
        raise BadInput(f"predictor {predictor!r}: {exc}") from None


def _check_aip_settings(predictor, aip_seeds, aip_lr_schedule, aip_influence_lags, aip_clock_horizon) -> int:
    """Clear errors for :func:`fidelity_report`'s AIP settings; returns ``aip_seeds`` as an int."""
    if isinstance(aip_seeds, bool) or not isinstance(aip_seeds, numbers.Integral) or aip_seeds < 1:
        raise BadInput(f"aip_seeds must be an int >= 1, got {aip_seeds!r}")
    if aip_lr_schedule is not None and aip_lr_schedule not in LR_SCHEDULES:
        raise BadInput(f"aip_lr_schedule must be one of {list(LR_SCHEDULES)} (or None: the domain's), "
                       f"got {aip_lr_schedule!r}")
    if aip_seeds > 1 and predictor not in ON_POLICY:
        raise BadInput(f"aip_seeds > 1 needs on-policy AIPs (trained per run); {predictor!r} is one fixed set")
    if aip_clock_horizon is not None:
        check_clock_horizon(aip_clock_horizon)
    if (aip_influence_lags is not None or aip_clock_horizon is not None) and predictor not in ON_POLICY:
        raise BadInput(f"aip_influence_lags and aip_clock_horizon need on-policy AIPs (trained per run); "
                       f"{predictor!r} is one fixed set")
    return int(aip_seeds)


def fidelity_report(env_id: str, policies: Sequence, episodes: int = 20, seed: int = 0, watched=None,
                    predictor="trained", tolerance: float = 0.1, progress: bool = True,
                    collect_steps: int | None = None, aip_lr: float | None = None, aip_epochs: int | None = None,
                    aip_seeds: int = 1, aip_lr_schedule: str | None = None,
                    aip_influence_lags: int | None = None, aip_clock_horizon: int | None = None,
                    ials_options: dict | None = None, **options) -> dict:
    """Run every joint policy on the GS and on the multi-agent IALS; returns
    ``{policy name: {agent: {metric: compare(...)}}}``. ``predictor``: an AIP set for every
    policy, or ``on-policy[-autoregressive]`` (module docstring) with ``collect_steps`` GS
    steps per policy (default: the domain's ``fidelity_collect_steps``, else its DIALS
    collection), ``aip_influence_lags`` (autoregressive only) and ``aip_clock_horizon``
    (default: the domain's). ``aip_seeds`` > 1 (on-policy AIPs
    only): train them that many times, from other GS data and training seeds, run the IALS with
    each set, and count per row in how many the row holds (``holds_in`` of ``aip_seeds``; the
    means and interval shown are the first set's): which rows fail moves from one training run
    to the next. ``ials_options`` go to the IALS only (``{"local": "arrays"}``: which local
    simulator, where the domain has a choice)."""
    from ials_zoo.influence.multi import make_ials_parallel_env  # lazy: SB3/torch

    aip_seeds = _check_aip_settings(predictor, aip_seeds, aip_lr_schedule, aip_influence_lags, aip_clock_horizon)
    domain = get_domain(env_id)
    agents = domain.agents(**options)
    sizes = joint_sizes(domain, agents, options)
    watched = list(watched or default_watched(domain, agents))
    report: dict = {"env_id": env_id, "episodes": episodes, "tolerance": tolerance, "watched": watched,
                    "predictor": str(predictor), "aip_lr": aip_lr, "aip_epochs": aip_epochs,
                    "aip_lr_schedule": aip_lr_schedule, "aip_influence_lags": aip_influence_lags,
                    "aip_seeds": aip_seeds, "ials_options": dict(ials_options or {}), "policies": {}}
    if predictor in ON_POLICY:
        (report["aip_lr"], report["aip_epochs"], report["aip_lr_schedule"],
         report["aip_influence_lags"]) = on_policy_training(env_id, predictor == "on-policy-autoregressive", aip_lr,
                                                            aip_epochs, aip_lr_schedule, aip_influence_lags)
    if predictor not in ON_POLICY:
        _check_aips_exist(env_id, agents, predictor, options)
    d = dials_of(domain)
    steps = int(collect_steps or d.fidelity_collect_steps or d.collect_steps)
    report["collect_steps"] = steps if predictor in ON_POLICY else None
    report["aip_clock_horizon"] = (d.fidelity_aip_clock_horizon if aip_clock_horizon is None else aip_clock_horizon) \
        if predictor in ON_POLICY else None
    for spec in policies:
        name = str(spec)
        policy = _joint_policy(spec, sizes, len(agents))
        if progress:
            print(f"fidelity {env_id}: {name}: GS ...", flush=True)
        gs_m = _gs_summary(domain, agents, watched, spec, policy, episodes, seed, options, sizes)
        if spec == "scripted":
            report["policies"][name] = {"gs_only": gs_m}
            continue
        if progress:
            print(f"fidelity {env_id}: {name}: IALS ...", flush=True)
        trainings = []
        for k in range(aip_seeds):
            aips = predictor
            if predictor in ON_POLICY:
                if progress:
                    print(f"fidelity {env_id}: {name}: AIPs from {steps:,} GS steps of this policy"
                          f"{f' (training {k + 1} of {aip_seeds})' if aip_seeds > 1 else ''} ...", flush=True)
                aips = on_policy_aips(env_id, agents, policy, steps, seed + DATA_SEED_OFFSET + k,
                                      predictor == "on-policy-autoregressive", options, aip_lr, aip_epochs,
                                      aip_lr_schedule, aip_influence_lags, report["aip_clock_horizon"],
                                      sizes.obs_size)
            ials_env = make_ials_parallel_env(env_id, agents, predictor=aips, seed=seed, **options, **(ials_options or {}))
            try:
                ials = run(ials_env, agents, watched, policy, episodes, seed, sizes)
            finally:
                ials_env.close()
            ials_m = summarise(ials, domain.null_influence)
            trainings.append({a: {m: compare(gs_m[a][m], ials_m[a][m], tolerance) for m in METRICS} for a in watched})
        report["policies"][name] = _merge_trainings(trainings, watched)
    return report


def _gs_summary(domain, agents, watched, spec, policy, episodes: int, seed: int, options: dict,
                sizes: JointSizes) -> dict:
    """The GS's episodes under one joint policy, summarised (the scripted controllers drive
    themselves: the learners' actions are ignored). The GS reports its regions' influence with
    the domain's ``collect_options`` (a real network watches its regions only when asked)."""
    gs_env = domain.parallel_env(learners=agents, scripted_learners=(spec == "scripted"),
                                 **{**domain.collect_options, **options})
    try:
        gs = run(gs_env, agents, watched, "constant" if spec == "scripted" else policy, episodes, seed, sizes)
    finally:
        gs_env.close()
    return summarise(gs, domain.null_influence)


def _merge_trainings(trainings: list[dict], watched) -> dict:
    """The first AIP training's rows (the report's means and interval), each with the votes of
    every training: under how many the row holds."""
    rows = trainings[0]
    for a in watched:
        for m in METRICS:
            votes = [t[a][m]["holds"] for t in trainings]
            counted = [h for h in votes if h is not None]
            rows[a][m].update(per_training=votes, ials_per_training=[t[a][m]["ials"] for t in trainings],
                              holds_in=sum(counted) if counted else None, trainings_compared=len(counted))
    return rows


def _summary_lines(report: dict) -> list[str]:
    """One row per joint policy: for each metric, how many watched agents' rows hold (under the
    first AIP training), so that a reader sees at a glance where the IALS departs from the GS."""
    compared = {n: rows for n, rows in report["policies"].items() if "gs_only" not in rows}
    if not compared:
        return []
    lines = ["| joint policy | " + " | ".join(METRICS) + " |", "|---" * (len(METRICS) + 1) + "|"]
    for name, rows in compared.items():
        cells = []
        for k in METRICS:
            held = [c[k]["holds"] for c in rows.values() if c[k]["holds"] is not None]
            cells.append(f"{sum(held)} / {len(held)}" if held else "-")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return ["Agents whose row holds, per joint policy and metric:", "", *lines, ""]


def markdown(report: dict) -> str:
    """The report as Markdown: a summary, then one table per joint policy."""
    training = ""
    if report.get("predictor") in ON_POLICY:
        schedule = {"linear": " decayed linearly to 0", "constant": " (constant)"}.get(report.get("aip_lr_schedule"), "")
        training = f", lr {report['aip_lr']:g}{schedule}, {report['aip_epochs']} epochs"
        lags = report.get("aip_influence_lags") or 0
        if lags:
            training += f", reading their last {lags} draw{'s' if lags > 1 else ''}"
        if report.get("aip_clock_horizon"):
            training += f", reading a clock (min(t, {report['aip_clock_horizon']}) / {report['aip_clock_horizon']})"
        if report.get("collect_steps"):
            training += f", trained on {report['collect_steps']:,} GS steps of each policy"
    n_trainings = int(report.get("aip_seeds", 1))
    if n_trainings > 1:
        training += (f"; {n_trainings} trainings of them, from other GS data: GS, IALS and the interval are the "
                     f"first's, `holds` counts the trainings under which the row holds")
    local = "".join(f", {k} {v}" for k, v in (report.get("ials_options") or {}).items())
    lines = [f"Fidelity of the multi-agent IALS{local} on `{report['env_id']}`: {report['episodes']} episodes per joint "
             f"policy, GS vs IALS (AIPs: {report.get('predictor', 'trained')}{training}), mean over episodes; a row holds "
             f"when the 95% Welch interval of GS - IALS contains 0 or |GS - IALS| <= {report['tolerance']:.0%} of the GS "
             "value.", ""]
    lines += _summary_lines(report)
    for name, rows in report["policies"].items():
        lines += [f"**{name}**", ""]
        if "gs_only" in rows:
            lines += ["(scripted controllers have no IALS form: GS values only)", "",
                      "| agent | " + " | ".join(METRICS) + " |", "|---" * (len(METRICS) + 1) + "|"]
            for a, m in rows["gs_only"].items():
                lines.append(f"| {a} | " + " | ".join(f"{np.nanmean(m[k]):.3f}" for k in METRICS) + " |")
            lines.append("")
            continue
        lines += ["| agent | metric | GS | IALS | GS - IALS (95%) | holds |", "|---|---|---|---|---|---|"]
        for a, metrics in rows.items():
            for k, c in metrics.items():
                holds = {True: "yes", False: "**no**", None: "-"}[c["holds"]]
                if n_trainings > 1 and c.get("holds_in") is not None:
                    compared = c["trainings_compared"]
                    holds = f"{c['holds_in']} / {compared}"
                    holds = holds if c["holds_in"] == compared else f"**{holds}**"
                lines.append(f"| {a} | {k} | {c['gs']:.3f} | {c['ials']:.3f} | [{c['low']:.3f}, {c['high']:.3f}] | "
                             f"{holds} |")
        lines.append("")
    return "\n".join(lines)


__all__ = ["METRICS", "ON_POLICY", "compare", "on_policy_aips", "on_policy_training", "default_watched", "episode_metrics", "fidelity_report", "markdown", "run",
           "summarise"]
