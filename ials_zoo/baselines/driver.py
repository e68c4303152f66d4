"""The training-run driver: what every baseline does around its learner.

A baseline (:mod:`.ippo`, :mod:`.dials`, :mod:`.ppo_single`, :mod:`.ppo_shared`) checks its
arguments, describes its run (:class:`RunPlan`) and hands the driver a small *learner adapter*
(:class:`Learner`): the part that owns the simulators and the PPO updates, and a *scoring
adapter* (:class:`Scoring`): how its policy is scored on the GS (the joint policy on the
multi-agent track, :class:`JointScoring`; one agent among scripted ones,
:class:`~ials_zoo.baselines.sb3_run.SingleAgentScoring`). The driver owns the rest, the same for
every learner:

- the run folder (:class:`~ials_zoo.baselines.runs.RunFolder`: claim, resume, overwrite,
  status) and the opening line;
- the training clock (GS evaluations and checkpoints excluded; AIP time charged), and the
  machine's speed on a reference workload at the start and at every checkpoint
  (:mod:`ials_zoo.reference_speed`: the wall-clock in reference seconds, ``training.reference``);
- the cadence: a GS evaluation of the policy every ``eval_every`` steps per agent, each one a
  learning-curve point and a checkpoint (and a checkpoint alone every ``checkpoint_every``);
  a ``progress.csv`` row per stretch of training; the learner's own stops (an AIP refresh) in
  between;
- the progress bar;
- the final policy, its GS scores (sampled, and deterministic) and the result files;
- the closing line.

A learner answers: its policy, its checkpoint (tensors + JSON: everything its future depends
on, so that a resumed run ends bitwise equal to the uninterrupted one), how to train up to a
number of steps per agent, and where it must stop before that (:meth:`Learner.next_stop`,
:meth:`Learner.before_training`).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from tqdm.auto import tqdm

import ials_zoo
from ials_zoo.baselines.multiagent import (
    TrainingLog,
    checkpoint_every_of,
    final_results,
    joint_policy,
    policy_file,
    settings_of,
    write_curve,
)
from ials_zoo.baselines.retrain import reproduce_record, training_command
from ials_zoo.baselines.runs import Clock, RunFolder, check_binding, load_training_state, save_training_state
from ials_zoo.core.extras import study_of
from ials_zoo.errors import BadInput
from ials_zoo.evaluation import evaluate_joint
from ials_zoo.leaderboard import now_iso
from ials_zoo.learners.gs_vec import GSVecEnv
from ials_zoo.reference_speed import ReferenceLog
from ials_zoo.utils import format_seconds


@dataclass
class RunPlan:
    """What the driver needs to know about a run, decided (and checked) by the baseline."""

    algorithm: str
    env_id: str
    agents: list
    options: dict
    seed: int
    total: int  # steps per agent, whole PPO updates
    per_update: int  # samples of each agent per PPO update
    eval_every: int
    eval_episodes: int
    final_eval_episodes: int
    frame_stack: int
    out: Path
    settings: dict  # what a resume must repeat (RunFolder)
    training: dict  # the result's training record; the driver fills steps and clocks
    resume: bool = False
    overwrite: bool = False
    progress: bool = True
    submitter: str = ""
    notes: str = ""
    meta: dict = field(default_factory=dict)  # the policy's metadata beyond the driver's
    checkpoint_every: int | None = None  # checkpoints between evaluations too (steps per agent)
    steps_per_second: float | None = None  # the study's speed, for the opening estimate (None: the multi-agent runs')
    unit: str = "step/agent"  # the progress bar's
    binding: dict = field(default_factory=dict)  # the run folder's (RunFolder.binding), in every checkpoint
    command: str = ""  # the `ials-zoo train` command of these settings (retrain.training_command)
    reference: ReferenceLog = field(default_factory=ReferenceLog)  # the machine's speed, kept in checkpoints


UNITS = {"step/agent": "steps per agent", "transition": "agent transitions"}
"""The closing line's words for a progress bar's unit (otherwise the unit plus an s)."""


class Learner(Protocol):
    """A learner adapter: the agents' PPO and the simulators it learns on."""

    simulator: str  # training.simulator, also the curve's header
    charged_seconds: float  # AIP seconds on the clock, excluded from training.wall_clock_seconds
    reports_aip_time: bool  # the closing line splits the wall-clock into training and AIPs
    log_columns: tuple  # progress.csv's columns (optional: PPO's, TrainingLog.COLUMNS)

    def load(self, state: dict | None, info: dict | None) -> None:
        """Before the clock starts: a fresh start (``None``) or a checkpoint to resume (what
        it makes before the clock starts, an AIP, is in :attr:`charged_seconds`)."""

    def start(self, steps: int) -> None:
        """Start the simulators and workers at ``steps`` per agent (on the clock), or put the
        loaded state into those :meth:`load` built."""

    def policy(self, metadata: dict):
        """The current policy as a :class:`~ials_zoo.policy.PolicyNetwork` carrying ``metadata``."""

    def next_stop(self, steps: int) -> int | None:
        """Steps per agent, after ``steps``, at which training must stop for the learner's own
        work (:meth:`before_training`); None: no stop."""

    def before_training(self, steps: int, total: int, policy: Callable, note: Callable[[str], None]) -> None:
        """The learner's own work due at ``steps`` (an AIP refresh), before any evaluation."""

    def train(self, steps: int, target: int, advance: Callable[[int], None]) -> dict:
        """Train from ``steps`` to ``target`` steps per agent; returns a ``progress.csv`` row."""

    def checkpoint(self, out: Path) -> tuple[dict, dict]:
        """``(tensors, JSON info)`` of a resumable state (may write its own files into ``out``):
        everything the run's future depends on. A learner whose episodes cannot be saved starts
        new, seeded ones here (the SB3 learners), so where checkpoints fall is part of the run."""

    def close(self) -> None: ...


class Scoring(Protocol):
    """A scoring adapter: how a run's policy is scored on the GS."""

    curve_header: dict  # what curve.json says beyond the run's id
    subject: str  # the closing line's: whose score the result is

    def curve(self, policy):
        """A learning-curve evaluation (``plan.eval_episodes``): an ``EvaluationResult``."""

    def final(self, path, training: dict, curve: list) -> tuple[dict, dict | None]:
        """Score the policy file at ``path`` and write the result files: ``(result,
        deterministic result or None)``."""

    def close(self, kill: bool = False) -> None: ...


class JointScoring:
    """The multi-agent track: the joint policy on the GS, every agent acting (scored sampled,
    ``result.json``, and deterministic, ``result_deterministic.json``)."""

    curve_header: dict = {}

    def __init__(self, plan: RunPlan):
        self.plan = plan
        self.subject = f"mean over {len(plan.agents)} agents"

    def curve(self, policy):
        return evaluate_joint(self.plan.env_id, policy, episodes=self.plan.eval_episodes, **self.plan.options)

    def final(self, path, training, curve):
        p = self.plan
        return final_results(p.out, p.env_id, path, p.algorithm, training, curve, p.agents, p.seed,
                             p.final_eval_episodes, p.options, p.submitter, p.notes, p.progress)

    def close(self, kill: bool = False) -> None:
        pass


class JointActors:
    """:meth:`Learner.policy` for a learner whose every agent has its own actor, stacked
    (:meth:`~ials_zoo.learners.batched_ppo.BatchedPPO.actor_layers`: ``[(W, b), ...]``, a
    recurrent actor's GRU first). The learner has ``agents``, ``obs_size``, ``n_actions``,
    ``frame_stack`` and ``actor_layers()``."""

    action_counts = None  # agents with action spaces of their own: each one's count
    activation = "tanh"  # after every hidden layer of the actors

    def policy(self, metadata: dict):
        return joint_policy(self.agents, self.actor_layers(), self.obs_size, self.n_actions, self.frame_stack,
                            metadata, self.action_counts, self.activation)


class CopiesLearner(JointActors):
    """The part of a learner adapter that every learner on copies of a simulator shares (IPPO,
    IDQN, DIALS on IALS copies): the copies as a multi-agent vector env, a trainer over seeded
    episodes (:class:`~ials_zoo.learners.rollout.SeededEpisodes`) whose episode in flight a
    resume replays, and a checkpoint of the learner's state and the trainer's. A subclass sets
    ``learner`` and makes the trainer (:meth:`_make_trainer`)."""

    simulator, charged_seconds, reports_aip_time = "gs", 0.0, False

    def _setup(self, env_id, agents, options, copies, processes, frame_stack, seed, sizes) -> None:
        self.env_id, self.agents, self.options, self.copies, self.processes = env_id, agents, options, copies, processes
        self.frame_stack, self.seed = frame_stack, seed
        self.obs_size, self.n_actions, self.action_counts = sizes.obs_size, sizes.n_actions, sizes.action_counts
        self.env = self.trainer = self.episode_state = None

    def load(self, state, info):
        if state is not None:
            self.learner.load_state_dict(state["learner"])
            self.episode_state = state.get("trainer")

    def _make_env(self):
        return GSVecEnv(self.env_id, self.agents, self.copies, self.processes, seed=self.seed, **self.options)

    def _make_trainer(self):
        raise NotImplementedError

    def start(self, steps):
        self.env = self._make_env()
        self.trainer = self._make_trainer()
        if self.episode_state is not None:  # the checkpoint's episodes, replayed to where they were
            self.trainer.restore(self.episode_state)

    def next_stop(self, steps):
        return None

    def before_training(self, steps, total, policy, note):
        pass

    def checkpoint(self, out):
        return {"learner": self.learner.state_dict(), "trainer": self.trainer.state()}, {}

    def close(self):
        if self.env is not None:
            self.env.close()


LATER_OPTIONS = ("train_reward", "imitate", "imitate_episodes")
"""Arguments added after runs were on the board: left out of a run's record at their default
(None), so that re-training an older entry still makes its policy file bit for bit."""


def _recorded(args) -> dict:
    return {k: v for k, v in dataclasses.asdict(args).items() if not (k in LATER_OPTIONS and v is None)}


def gs_run_plan(algorithm: str, args, agents: list, options: dict, total: int, per_update: int, frame_stack: int,
                processes: int, hyperparameters: dict) -> RunPlan:
    """The plan of a run in which every agent learns on GS copies (IPPO, IDQN): the budget,
    cadence, folder and training record from ``args`` (:class:`~.multiagent.JointRunArgs`),
    with the learner's own ``hyperparameters`` recorded beside the arguments."""
    eval_every = int(args.eval_every or max(per_update, total // 10))
    training = {"simulator": "gs", "aip": None, "seeds": [args.seed], "env_steps": 0, "wall_clock_seconds": 0.0,
                "aip_seconds": 0.0, "workers": max(processes, 1),
                "hyperparameters": dict(_recorded(args), agents=agents, total_timesteps=total,
                                        eval_every=eval_every, **hyperparameters, gs_processes=processes)}
    return RunPlan(algorithm, args.env_id, agents, options, args.seed, total, per_update, eval_every,
                   args.eval_episodes, args.final_eval_episodes, frame_stack,
                   Path(args.out_dir or f"runs/{args.env_id}__{algorithm}__s{args.seed}"),
                   settings_of(args, skip=("resume", "overwrite", "progress", "out_dir", "submitter", "notes",
                                           "gs_processes", "checkpoint_every")),
                   training, args.resume, args.overwrite, args.progress, args.submitter, args.notes,
                   checkpoint_every=checkpoint_every_of(args, eval_every, per_update),
                   command=training_command(algorithm, args))


def estimate_text(plan: RunPlan, learner: Learner, domain) -> str:
    """The opening line's budget: the expected training time at the study's measured speed."""
    study = study_of(domain)
    if plan.steps_per_second is not None:
        seconds = plan.total / max(plan.steps_per_second, 1.0)
        unit = UNITS.get(plan.unit, plan.unit + "s")
        return (f"{plan.total:,} {unit}; about {format_seconds(seconds)} of training at the study's speed "
                f"({plan.steps_per_second:,.0f} {unit}/s on 2 cores; evaluations extra)")
    seconds, speed = _multi_agent_seconds(plan, learner.simulator == "gs", study, domain)
    return (f"{plan.total:,} steps per agent; about {format_seconds(seconds)} of training at the study's speed "
            f"({speed} on 2 cores; evaluations extra)")


def _multi_agent_seconds(plan: RunPlan, on_gs: bool, study, domain) -> tuple[float, str]:
    """A multi-agent run's expected training seconds, and the speed they assume (words)."""
    simulator = "gs" if on_gs else "ials"
    if study.joint_step_seconds is not None:  # the map's cost, whatever the number of learners
        step = max(float(study.joint_step_seconds(simulator, **plan.options)), 1e-6)
        return plan.total * step, f"{1 / step:,.0f} steps of all agents at once per second"
    rate = study.multi_agent_steps_per_second.get(simulator, 10_000.0)
    seconds = plan.total * len(plan.agents) / max(rate, 1.0)
    if on_gs and len(plan.agents) < len(domain.agents(**plan.options)):
        # the GS also moves the scripted agents: about what one learner on the GS costs in
        # ppo_single (robot_20 alone, 512k steps: this says 2.0 min, it took 1.6-2.0)
        seconds += plan.total / max(study.ppo_steps_per_second.get("gs", 1000.0), 1.0)
    return seconds, f"{rate:,.0f} agent-steps/s"


def run(plan: RunPlan, learner: Learner, description: str, domain, scoring: Scoring | None = None) -> dict:
    """Drive ``learner`` through ``plan``; returns the sampled result (also ``result.json``, or
    the scoring's files). ``scoring``: the multi-agent track's (:class:`JointScoring`) unless
    given. ``description`` opens the run's first line (the driver adds the budget and the
    folder)."""
    out = plan.out
    scoring = scoring or JointScoring(plan)
    folder = RunFolder(out, resume=plan.resume, overwrite=plan.overwrite, settings=plan.settings)
    plan.binding = folder.binding()
    print(f"{description}\n  {estimate_text(plan, learner, domain)}; writing {out}/"
          + (" (resuming)" if folder.resuming else ""), flush=True)
    meta = dict({"algorithm": plan.algorithm, "env_id": plan.env_id, "env_options": plan.options, "seed": plan.seed,
                 "package_version": ials_zoo.__version__, "created": now_iso()}, **plan.meta)
    training = plan.training
    if plan.command:  # what re-trains it (ials-zoo leaderboard verify --retrain)
        training["reproduce"] = reproduce_record(plan.command)
    ok = False
    with folder.running():
        log = TrainingLog(out / "progress.csv", getattr(learner, "log_columns", TrainingLog.COLUMNS),
                          agents=plan.agents if len(plan.agents) > 1 else None)
        steps, curve = 0, []
        try:
            try:
                # inside: a load or start that fails half-way still closes what it started
                state = info = None
                if folder.resuming:
                    state, info = _load_checkpoint(out, plan.binding)
                    plan.reference = ReferenceLog(info.get("reference"))
                plan.reference.sample()  # the machine's speed now, off the clock (it starts below)
                learner.load(state, info)
                if folder.resuming:
                    steps, curve = int(info["steps"]), info["curve"]
                    log.truncate(steps)
                    clock = Clock(offset=float(info["clock"]))
                else:
                    clock = Clock(offset=learner.charged_seconds)
                learner.start(steps)

                def policy_net():
                    return learner.policy(dict(meta, training=training, learning_curve=curve))

                steps = _train(plan, learner, scoring, policy_net, log, clock, steps, curve)
                charged = learner.charged_seconds
                training.update(env_steps=steps, wall_clock_seconds=clock.seconds - charged, aip_seconds=charged,
                                reference=plan.reference.record(clock.seconds))
                path = policy_file(out, policy_net())
            finally:
                learner.close()
            result, deterministic = scoring.final(path, training, curve)
            ok = True
        finally:
            scoring.close(kill=not ok)
    s = result["score"]
    seconds = training["wall_clock_seconds"] + training["aip_seconds"]
    split = (f" (of which AIP collection and training {format_seconds(training['aip_seconds'])})"
             if learner.reports_aip_time else "")
    det = "" if deterministic is None else f"; deterministic {deterministic['score']['mean']:.3f}"
    rank = domain.score_metric  # a domain ranked by a metric (RESCO's delay): say it first
    if rank is not None and rank in (result.get("metrics") or {}):
        m = result["metrics"][rank]
        print(f"{plan.algorithm}: {rank} {m['mean']:.3f} [{m['ci_low']:.3f}, {m['ci_high']:.3f}] "
              f"({domain.metrics[rank]} is better; it ranks the board)", flush=True)
    print(f"{plan.algorithm}: GS score ({scoring.subject}) {s['mean']:.3f} "
          f"[{s['ci_low']:.3f}, {s['ci_high']:.3f}] after {steps:,} {UNITS.get(plan.unit, plan.unit + 's')}; "
          f"wall-clock {format_seconds(seconds)}{split}{det}; wrote {out}/", flush=True)
    return result


def _train(plan: RunPlan, learner: Learner, scoring: Scoring, policy_net, log: TrainingLog, clock: Clock,
           steps: int, curve: list) -> int:
    """The cadence, from ``steps`` to the budget: training stretches between evaluations,
    checkpoints and the learner's own stops. Evaluations and checkpoints keep to fixed grids
    (multiples of ``eval_every`` and ``checkpoint_every``), each at the first whole update at or
    past its point; a learner's stop comes at the last whole update before it. Returns the
    steps reached."""
    per = plan.per_update
    bar = _Bar(plan, steps)
    next_eval = _after(curve[-1]["env_steps"], plan.eval_every) if curve else 0
    every = plan.checkpoint_every
    next_checkpoint = _after(steps, every) if every else None
    while True:
        if steps < plan.total:
            learner.before_training(steps, plan.total, policy_net, bar.note)
        scored = bool(curve) and curve[-1]["env_steps"] == steps  # a resume at the very end
        if (steps >= next_eval or steps >= plan.total) and not scored:
            with clock.pause():
                score = _curve_point(plan, learner, scoring, policy_net(), steps, curve, clock)
            bar.score(score)
            next_eval = _after(steps, plan.eval_every)
        elif next_checkpoint is not None and steps >= next_checkpoint and not scored:
            with clock.pause():
                _checkpoint(plan, learner, steps, curve, clock)
        if next_checkpoint is not None and steps >= next_checkpoint:
            next_checkpoint = _after(steps, every)
        if steps >= plan.total:
            break
        target = min(plan.total, -(-next_eval // per) * per,
                     -(-next_checkpoint // per) * per if next_checkpoint is not None else plan.total)
        stop = learner.next_stop(steps)
        if stop is not None:
            target = min(target, stop // per * per)
        target = max(steps + per, target)
        started = time.perf_counter()
        row = learner.train(steps, target, bar.advance)
        _say_measured_speed(plan, steps, target, time.perf_counter() - started, bar)
        steps = target
        log.add(dict(row, steps_per_agent=steps, wall_clock_seconds=round(clock.seconds, 3)))
        bar.reach(steps)
    bar.close()
    return steps


def _say_measured_speed(plan: RunPlan, start: int, end: int, seconds: float, bar) -> None:
    """Once, after the first stretch of training: this machine's speed and what it makes of the
    rest (the opening line's estimate is the study's speed; machines differ 2-4x)."""
    if bar.speed_said or end >= plan.total or seconds <= 0:
        return
    bar.speed_said = True
    rate = (end - start) / seconds
    unit = UNITS.get(plan.unit, plan.unit + "s")
    joint = f" ({rate * len(plan.agents):,.0f} agent-steps/s)" if plan.steps_per_second is None else ""
    text = (f"  measured here: {rate:,.0f} {unit}/s{joint} over the first {end - start:,}; about "
            f"{format_seconds((plan.total - end) / max(rate, 1e-9))} of training left (GS evaluations extra)")
    bar.write(text)


def _after(steps: int, every: int) -> int:
    """The first multiple of ``every`` past ``steps``."""
    return (steps // every + 1) * every


def _curve_point(plan: RunPlan, learner, scoring: Scoring, policy, steps: int, curve: list, clock: Clock) -> float:
    """A GS evaluation of the policy: a learning-curve point and a checkpoint."""
    ev = scoring.curve(policy)
    curve.append({"env_steps": steps, "wall_clock_seconds": clock.seconds, "mean": ev.mean, "ci_low": ev.ci_low,
                  "ci_high": ev.ci_high})
    write_curve(plan.out, dict({"env_id": plan.env_id, "algorithm": plan.algorithm, "seed": plan.seed},
                               **scoring.curve_header, simulator=learner.simulator), curve)
    _checkpoint(plan, learner, steps, curve, clock)
    return ev.mean


def _checkpoint(plan: RunPlan, learner, steps: int, curve: list, clock: Clock) -> None:
    plan.reference.sample()  # off the clock: every checkpoint is taken in a pause
    tensors, info = learner.checkpoint(plan.out)
    # the steps in both files: a run killed between the two writes leaves them apart
    save_training_state(plan.out, dict(tensors, driver_steps=steps, run_id=plan.binding.get("run_id")),
                        dict(info, steps=steps, curve=curve, clock=clock.seconds, run=plan.binding,
                             reference=plan.reference.record()))


def _load_checkpoint(out: Path, binding: dict) -> tuple[dict, dict]:
    """The checkpoint in ``out``, if it is this run's (:func:`check_binding`) and whole."""
    state, info = load_training_state(out)
    check_binding(out, state, info, binding)
    steps, curve, clock = info.get("steps"), info.get("curve"), info.get("clock")
    if (isinstance(steps, bool) or not isinstance(steps, int) or steps < 0 or not isinstance(curve, list)
            or not all(isinstance(p, dict) and isinstance(p.get("env_steps"), int) for p in curve)
            or isinstance(clock, bool) or not isinstance(clock, (int, float)) or not clock >= 0):
        raise BadInput(f"{out}: checkpoint.json is not a checkpoint of ours (steps, curve and clock); it cannot be "
                       "resumed: start the run again with --overwrite")
    if int(state.pop("driver_steps", info["steps"])) != int(info["steps"]):
        raise BadInput(f"{out}: checkpoint.pt and checkpoint.json are from different checkpoints (the run was killed "
                       "while writing them); it cannot continue exactly: start it again with --overwrite")
    return state, info


class _Bar:
    """The run's progress bar (steps per agent), or nothing with ``progress=False``."""

    def __init__(self, plan: RunPlan, steps: int):
        self.speed_said = False  # this machine's speed is said once, after the first stretch
        self.bar = None
        if plan.progress:
            self.bar = tqdm(total=plan.total, initial=steps, unit=plan.unit, dynamic_ncols=True,
                            desc=plan.algorithm)

    def write(self, text: str) -> None:
        """A line above the bar (or a plain line without one)."""
        if self.bar is not None:
            self.bar.write(text)
        else:
            print(text, flush=True)

    def note(self, text: str) -> None:
        if self.bar is not None:
            self.bar.set_postfix_str(text)

    def score(self, mean: float) -> None:
        if self.bar is not None:
            self.bar.set_postfix(gs=f"{mean:.2f}")

    def advance(self, n: int) -> None:
        if self.bar is not None:
            self.bar.update(n)

    def reach(self, steps: int) -> None:
        if self.bar is not None:
            self.bar.update(steps - self.bar.n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def check_run_args(args) -> None:
    """Clear errors for the arguments every multi-agent run shares."""
    for name in ("eval_episodes", "final_eval_episodes"):
        if getattr(args, name) < 1:
            raise BadInput(f"{name} must be >= 1, got {getattr(args, name)}")
    for name in ("n_envs", "total_timesteps", "eval_every"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise BadInput(f"{name} must be >= 1, got {v}")
    if (getattr(args, "checkpoint_every", None) or 0) < 0:
        raise BadInput(f"checkpoint_every must be >= 0 (0: at evaluations only), got {args.checkpoint_every}")


__all__ = ["CopiesLearner", "JointActors", "JointScoring", "Learner", "RunPlan", "Scoring", "check_run_args", "estimate_text",
           "gs_run_plan", "run"]
