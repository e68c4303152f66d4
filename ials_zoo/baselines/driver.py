"""The multi-agent training-run driver: what every multi-agent baseline does around its learner.

A baseline (:mod:`.ippo`, :mod:`.dials`) checks its arguments, describes its run
(:class:`RunPlan`) and hands the driver a small *learner adapter* (:class:`MultiAgentLearner`):
the part that owns the simulators and the PPO updates. The driver owns the rest, the same for
every learner:

- the run folder (:class:`~ials_zoo.baselines.runs.RunFolder`: claim, resume, overwrite,
  status) and the opening line;
- the training clock (GS evaluations and checkpoints excluded; AIP time charged);
- the cadence: a GS evaluation of the joint policy every ``eval_every`` steps per agent, each
  one a learning-curve point and a checkpoint; a ``progress.csv`` row per stretch of training;
  the learner's own stops (an AIP refresh) in between;
- the progress bar;
- the final joint policy, its two GS scores (sampled and deterministic) and ``result.json``;
- the closing line.

An adapter answers: its actors' layers, its checkpoint (tensors + JSON), how to train up to a
number of steps per agent, and where it must stop before that (:meth:`next_stop`,
:meth:`before_training`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np
from tqdm.auto import tqdm

import ials_zoo
from ials_zoo.baselines.multiagent import TrainingLog, final_results, joint_policy, policy_file, write_curve
from ials_zoo.baselines.runs import Clock, RunFolder, load_training_state, save_training_state
from ials_zoo.core.extras import study_of
from ials_zoo.errors import BadInput
from ials_zoo.evaluation import evaluate_joint
from ials_zoo.leaderboard import now_iso
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
    meta: dict = field(default_factory=dict)


class MultiAgentLearner(Protocol):
    """A learner adapter: every agent's PPO and the simulators it learns on."""

    simulator: str  # training.simulator, also the curve's header
    charged_seconds: float  # AIP seconds on the clock, excluded from training.wall_clock_seconds
    reports_aip_time: bool  # the closing line splits the wall-clock into training and AIPs

    def load(self, state: dict | None, info: dict | None) -> None:
        """Before the clock starts: a fresh start (``None``) or a checkpoint to resume."""

    def start(self, steps: int) -> None:
        """Start the simulators and workers at ``steps`` per agent (on the clock)."""

    def actor_layers(self) -> list:
        """Every layer of every agent's actor, stacked over agents: ``[(W, b), ...]``, a recurrent
        actor's GRU first (:meth:`~ials_zoo.learners.batched_ppo.BatchedPPO.actor_layers`)."""

    def next_stop(self, steps: int) -> int | None:
        """Steps per agent, after ``steps``, at which training must stop for the learner's own
        work (:meth:`before_training`); None: no stop."""

    def before_training(self, steps: int, total: int, policy: Callable, note: Callable[[str], None]) -> None:
        """The learner's own work due at ``steps`` (an AIP refresh), before any evaluation."""

    def train(self, steps: int, target: int, advance: Callable[[int], None]) -> dict:
        """Train from ``steps`` to ``target`` steps per agent; returns a ``progress.csv`` row."""

    def checkpoint(self, out: Path) -> tuple[dict, dict]:
        """``(tensors, JSON info)`` of a resumable state (may write its own files into ``out``)."""

    def close(self) -> None: ...


def run(plan: RunPlan, learner: MultiAgentLearner, description: str, domain) -> dict:
    """Drive ``learner`` through ``plan``; returns the sampled result (also ``result.json``).

    ``description`` opens the run's first line (the driver adds the budget and the folder)."""
    out = plan.out
    folder = RunFolder(out, resume=plan.resume, overwrite=plan.overwrite, settings=plan.settings)
    on_gs = learner.simulator == "gs"
    study = study_of(domain)
    rate = study.multi_agent_steps_per_second.get("gs" if on_gs else "ials", 10_000.0)
    estimate = plan.total * len(plan.agents) / max(rate, 1.0)
    if on_gs and len(plan.agents) < len(domain.agents(**plan.options)):
        # the GS also moves the scripted agents: about what one learner on the GS costs in
        # ppo_single (robot_20 alone, 512k steps: this says 2.0 min, it took 1.6-2.0)
        estimate += plan.total / max(study.ppo_steps_per_second.get("gs", 1000.0), 1.0)
    print(f"{description}\n  {plan.total:,} steps per agent; about {format_seconds(estimate)} of training at the "
          f"study's speed ({rate:,.0f} agent-steps/s on 2 cores; evaluations extra); writing {out}/"
          + (" (resuming)" if folder.resuming else ""), flush=True)
    meta = dict({"algorithm": plan.algorithm, "env_id": plan.env_id, "env_options": plan.options, "seed": plan.seed,
                 "package_version": ials_zoo.__version__, "created": now_iso()}, **plan.meta)
    training = plan.training
    obs_size = int(np.prod(domain.observation_space.shape))
    with folder.running():
        log = TrainingLog(out / "progress.csv")
        steps, curve = 0, []
        if folder.resuming:
            state, info = load_training_state(out)
            learner.load(state, info)
            steps, curve = int(info["steps"]), info["curve"]
            log.truncate(steps)
            clock = Clock(offset=float(info["clock"]))
        else:
            learner.load(None, None)
            clock = Clock(offset=learner.charged_seconds)
        try:
            learner.start(steps)  # inside: a start that fails half-way still closes what it started

            def policy_net():
                return joint_policy(plan.agents, learner.actor_layers(), obs_size, domain.n_actions, plan.frame_stack,
                                    dict(meta, training=training, learning_curve=curve))

            bar = _Bar(plan, steps)
            next_eval = curve[-1]["env_steps"] + plan.eval_every if curve else 0
            while True:
                if steps < plan.total:
                    learner.before_training(steps, plan.total, policy_net, bar.note)
                if steps >= next_eval or steps >= plan.total:
                    with clock.pause():
                        score = _curve_point(plan, learner, policy_net(), steps, curve, clock)
                    bar.score(score)
                    next_eval = steps + plan.eval_every
                if steps >= plan.total:
                    break
                target = min(plan.total, next_eval)
                stop = learner.next_stop(steps)
                if stop is not None:
                    target = min(target, stop)
                target = max(steps + plan.per_update, target // plan.per_update * plan.per_update)
                row = learner.train(steps, target, bar.advance)
                steps = target
                log.add(dict(row, steps_per_agent=steps, wall_clock_seconds=round(clock.seconds, 3)))
                bar.reach(steps)
            bar.close()
            charged = learner.charged_seconds
            training.update(env_steps=steps, wall_clock_seconds=clock.seconds - charged, aip_seconds=charged)
            path = policy_file(out, policy_net())
        finally:
            learner.close()
        result, deterministic = final_results(out, plan.env_id, path, plan.algorithm, training, curve, plan.agents,
                                              plan.seed, plan.final_eval_episodes, plan.options, plan.submitter,
                                              plan.notes, plan.progress)
    s = result["score"]
    seconds = training["wall_clock_seconds"] + training["aip_seconds"]
    split = (f" (of which AIP collection and training {format_seconds(training['aip_seconds'])})"
             if learner.reports_aip_time else "")
    print(f"{plan.algorithm}: GS score (mean over {len(plan.agents)} agents) {s['mean']:.3f} "
          f"[{s['ci_low']:.3f}, {s['ci_high']:.3f}] after {steps:,} steps per agent; wall-clock "
          f"{format_seconds(seconds)}{split}; deterministic {deterministic['score']['mean']:.3f}; "
          f"wrote {out}/result.json", flush=True)
    return result


def _curve_point(plan: RunPlan, learner, policy, steps: int, curve: list, clock: Clock) -> float:
    """A GS evaluation of the joint policy: a learning-curve point and a checkpoint."""
    ev = evaluate_joint(plan.env_id, policy, episodes=plan.eval_episodes, **plan.options)
    curve.append({"env_steps": steps, "wall_clock_seconds": clock.seconds, "mean": ev.mean, "ci_low": ev.ci_low,
                  "ci_high": ev.ci_high})
    write_curve(plan.out, {"env_id": plan.env_id, "algorithm": plan.algorithm, "seed": plan.seed,
                           "simulator": learner.simulator}, curve)
    tensors, info = learner.checkpoint(plan.out)
    save_training_state(plan.out, tensors, dict(info, steps=steps, curve=curve, clock=clock.seconds))
    return ev.mean


class _Bar:
    """The run's progress bar (steps per agent), or nothing with ``progress=False``."""

    def __init__(self, plan: RunPlan, steps: int):
        self.bar = None
        if plan.progress:
            self.bar = tqdm(total=plan.total, initial=steps, unit="step/agent", dynamic_ncols=True,
                            desc=plan.algorithm)

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


__all__ = ["MultiAgentLearner", "RunPlan", "check_run_args", "run"]
