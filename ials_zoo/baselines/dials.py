"""DIALS: every agent learns at once, each on its own IALS, spread over workers (SPEC §6).

Usage::

    ials-zoo train dials --env traffic_grid_v0                       # periodic AIP refresh
    ials-zoo train dials --env warehouse_v0 --refresh once           # AIPs trained once, at the start
    ials-zoo train dials --env traffic_grid_v0 --aip untrained --refresh never   # untrained-DIALS
    ials-zoo train dials --env traffic_grid_v0 --aip-training fidelity   # AIPs as `ials-zoo fidelity` trains them
    ials-zoo train dials --env warehouse_v0 --backend ray [--ray-address host:6379]
    python -m baselines.dials --help

The loop (the authors' follow-up, SPEC §6):

1. every ``--refresh`` steps per agent (``once``: only at step 0; ``never``: keep the initial
   AIPs) the current joint policy runs on the GS for ``--collect-steps`` steps, recording
   ``(d_t, u_t)`` of every region in one run, and every agent's AIP is retrained on that data
   (warm start; one stacked torch program for all agents). The data of a collection replaces
   the previous one. Round 0's data come from a uniformly random joint policy (the initial
   policies are near-uniform);
2. every ``--eval-every`` steps per agent the joint policy is scored on the GS (every agent
   acting; :func:`ials_zoo.evaluation.evaluate_joint`, ``--eval-episodes`` of the fixed seeds),
   and the run is checkpointed;
3. in between, every agent trains with its own PPO on its own IALS; the agents are split over
   ``--workers`` worker processes (default: one per core) or Ray actors (``--backend ray``),
   each holding its agents' local simulators and AIPs in one batch
   (:mod:`ials_zoo.dials.shard`).

``--aip-training``: ``dials`` (the domain's DIALS AIP settings) or ``fidelity`` (the settings
with which ``ials-zoo fidelity``'s on-policy AIPs reproduce the GS's influence over whole
trajectories, :func:`aip_training_of`: autoregressive, maybe reading more of their own past and
a clock, trained on more GS steps for more epochs; slower rounds). Unlike the report's, which
start from scratch, a round's AIPs start from the last round's.

``--aip``: ``trained`` (collected and trained at step 0, timed), ``untrained`` (random
networks), ``uniform``, ``fixed:P``, ``shipped`` (the AIPs that ship with the package) or a
predictor-set file. Only what the run does is on its clock: a shipped set's or a file's
recorded collection and training seconds are reported in ``training.aip`` (``charged:
false``), not added.

**Learners**: ``--learner batched`` (default: every agent's PPO in one torch program,
:mod:`ials_zoo.learners.batched_ppo`) or ``sb3`` (one stable-baselines3 PPO per agent, the
reference). **Determinism**: everything an agent does depends only on the run seed and its
name, not on its worker: the same seed gives the same run on either backend and with any
``--workers`` (bitwise on this CPU and torch build; see :mod:`ials_zoo.learners.batched_ppo`).

**Wall-clock**: ``training.wall_clock_seconds`` is the learners' training alone and
``training.aip_seconds`` the AIPs' data collection and training; the run's wall-clock is their
sum, which the curve's ``wall_clock_seconds`` counts (as in the paper's plots) and the
leaderboard shows as "wall-clock (+AIP)"; GS evaluations and checkpoints excluded. Outputs in ``--out-dir`` as for the other baselines
(:mod:`ials_zoo.baselines.runs`): ``status.json``, ``progress.csv``, ``curve.json``,
``checkpoint.pt``/``checkpoint.json`` + ``aips.pt`` (every round: ``--resume`` continues a
killed run), ``policy.safetensors`` (the joint policy) and ``result.json`` (multi-agent track).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ials_zoo.baselines.aip_rounds import (
    AIPRefreshes,
    aip_training_of,
    parse_refresh,
)
from ials_zoo.baselines.arguments import arg, run_cli
from ials_zoo.baselines.dials_copies import IALSCopiesLearner
from ials_zoo.baselines.driver import JointActors, RunPlan, check_run_args, run
from ials_zoo.baselines.multiagent import (
    MultiAgentRunArgs,
    check_multi_ppo,
    checkpoint_every_of,
    env_options_of,
    frame_stack_of,
    merge_shard_stats,
    ppo_config,
    save_aips,
    settings_of,
    whole_updates,
)
from ials_zoo.baselines.retrain import training_command
from ials_zoo.core.domains import LOCAL_SIMULATORS, dials_domain_ids, get_domain
from ials_zoo.core.extras import dials_of, study_of
from ials_zoo.core.spaces import joint_sizes
from ials_zoo.dials.backends import BACKENDS, InProcessBackend, check_ray_address, make_backend
from ials_zoo.dials.shard import LEARNERS, PPO_CLASSES, ShardSpec, split_agents
from ials_zoo.errors import BadInput
from ials_zoo.influence.fidelity import on_policy_training
from ials_zoo.influence.multi import shipped_set_path
from ials_zoo.influence.specs import parse_predictor
from ials_zoo.utils import check_seed

REFRESH_WORDS = ("default", "once", "never")
# "dials": the domain's DIALS AIP training (DIALSSettings.aip_*, collect_steps); "fidelity": the
# training with which `ials-zoo fidelity`'s on-policy AIPs reproduce the GS over whole
# trajectories (DIALSSettings.fidelity_*: autoregressive, more data and epochs, maybe a clock)
AIP_TRAININGS = ("dials", "fidelity")


def _per_domain(describe) -> str:
    """``"<env_id> <what>, ..."`` for every domain DIALS trains on (help texts read from the data)."""
    return ", ".join(f"{env_id} {describe(get_domain(env_id))}" for env_id in dials_domain_ids())


def _fidelity_text(domain) -> str:
    d = dials_of(domain)
    lr, epochs, schedule, lags = on_policy_training(domain.env_id, True)
    clock = f", clock {d.fidelity_aip_clock_horizon}" if d.fidelity_aip_clock_horizon else ""
    return (f"{(d.fidelity_collect_steps or d.collect_steps):,} GS steps, last {lags} draw{'s' if lags > 1 else ''}"
            f"{clock}, lr {lr:g} {schedule} x {epochs} epochs")


def _refresh_text(domain) -> str:
    refresh = dials_of(domain).refresh
    return "once" if refresh == 0 else "never" if refresh is None else f"every {refresh:,}"


@dataclass
class Args(MultiAgentRunArgs):
    """Arguments of :func:`main` (``python -m baselines.dials --help``)."""

    refresh: str = arg("default", lambda: "retrain the AIPs every N steps per agent, 'once' (at the start), 'never', "
                       f"or 'default' (the domain's: {_per_domain(_refresh_text)})")
    aip: str = arg("trained", "initial AIPs: trained | untrained | uniform | fixed:P | shipped | FILE.pt")
    collect_steps: int | None = arg(None, lambda: "GS steps per data collection (default: the domain's: "
                                    f"{_per_domain(lambda d: f'{dials_of(d).collect_steps:,}')}; with "
                                    "--aip-training fidelity: " + _per_domain(
                                        lambda d: f'{dials_of(d).fidelity_collect_steps or dials_of(d).collect_steps:,}')
                                    + ")")
    aip_epochs: int | None = arg(None, "epochs per AIP (re)training (default: the domain's)")
    aip_lr: float | None = arg(None, "learning rate of the AIP (re)training (default: the domain's for the kind "
                               "of AIP, memoryless or autoregressive, or for --aip-training fidelity)")
    aip_autoregressive: bool | None = arg(None, lambda: "AIPs that also read the influence they sampled at the "
                                          "previous step, P(u_t | d_<=t, u_<t) (default: the domain's: " + _per_domain(
                                              lambda d: "yes" if dials_of(d).aip_autoregressive else "no") + ")")
    aip_training: str = arg("dials", lambda: "how the AIPs are trained: 'dials' (the domain's DIALS settings) or "
                            "'fidelity' (the settings of `ials-zoo fidelity`'s on-policy AIPs, which reproduce the "
                            "GS's influence over whole trajectories, warm-started from the last round: "
                            + _per_domain(_fidelity_text) + "). --collect-steps, --aip-epochs, --aip-lr override either")
    n_envs: int | None = arg(None, lambda: f"IALS copies per agent (default: the domain's: "
                             f"{_per_domain(lambda d: str(dials_of(d).copies))})")
    local: str = arg("sumo", "the agents' local simulators, where the domain has a choice: sumo (every region cut "
                     "from the network, one SUMO simulation per copy) | arrays (every region of every copy as numpy "
                     "arrays, one batch: ials_zoo.sumo_net.arrays)")
    learner: str = arg("batched", "batched (every agent's own PPO in one torch program: IPPO's) | shared (one "
                       "actor-critic for every agent with its id: shared_ppo's; one worker on a batched IALS) | sb3 "
                       "(one SB3 PPO per agent)")
    workers: int | None = arg(None, "worker processes (default: one per core; 0: this process)")
    backend: str = arg("process", "process | ray")
    ray_address: str | None = arg(None, "an existing Ray cluster (host:port); default: a new local Ray of the run's "
                                  "own (RAY_ADDRESS and clusters running here are not joined)")
    out_dir: str | None = arg(None, "output folder (default: runs/<env>__dials__s<seed>)")


def check_args(args: Args):
    """Clear errors before anything starts; returns (domain, agents, options, refresh, copies)."""
    if args.env_id is None:
        raise BadInput(f"name the domain to train on: --env, one of {', '.join(dials_domain_ids())}")
    domain = get_domain(args.env_id)
    if on_copies(domain):
        _check_copies_args(args)
    else:
        domain.require_ials("train dials")
        if args.local != "sumo":
            raise BadInput(f"--local {args.local}: {args.env_id}'s agents share one batched local simulator already")
    options = env_options_of(args, domain)
    domain.check_ials_options(options, "train dials")
    agents = domain.check_agents(None if args.agents == "all" else args.agents, **options)
    check_seed(args.seed, "seed")
    check_multi_ppo(args, domain)
    refresh = parse_refresh(args.refresh, dials_of(domain).refresh)
    if args.aip_training not in AIP_TRAININGS:
        raise BadInput(f"unknown aip_training {args.aip_training!r}; expected one of {AIP_TRAININGS}")
    if args.aip_training == "fidelity":
        if args.aip != "trained" or refresh is None:
            raise BadInput("--aip-training fidelity is how DIALS trains its AIPs: it needs --aip trained and a refresh")
        if args.aip_autoregressive is False:
            raise BadInput("--aip-training fidelity trains autoregressive AIPs: drop --aip-autoregressive no")
    if args.aip == "trained" and refresh is None:
        raise BadInput("--aip trained --refresh never would never train the AIPs: use --refresh once, or --aip "
                       "untrained for untrained-DIALS")
    if args.aip == "shipped":
        if not shipped_set_path(args.env_id).is_file():
            raise BadInput(f"--aip shipped: no AIPs ship for {args.env_id}")
        if refresh is not None:
            raise BadInput("--aip shipped is a fixed AIP set: use --refresh never (retraining would replace it)")
    else:
        spec = parse_predictor(args.aip)
        if spec.kind == "file" and not os.path.isfile(spec.path):
            raise BadInput(f"--aip {args.aip!r}: file not found")
        if spec.kind not in ("trained", "file") and refresh is not None:
            raise BadInput(f"--aip {args.aip} is a fixed AIP: use --refresh never (retraining would replace it)")
    check_run_args(args)
    if args.aip_lr is not None and not (math.isfinite(args.aip_lr) and args.aip_lr > 0):
        raise BadInput(f"aip_lr must be a finite number > 0, got {args.aip_lr}")
    for name in ("collect_steps", "aip_epochs"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise BadInput(f"{name} must be >= 1, got {v}")
    copies = int(args.n_envs or dials_of(domain).copies)
    ppo_config(args, copies, frame_stack_of(args, domain))
    if args.recurrent_hidden and args.learner != "batched":
        raise BadInput("--recurrent-hidden needs --learner batched (the SB3 learner's policies are MLPs)")
    if args.workers is not None and args.workers < 0:
        raise BadInput(f"workers must be >= 0, got {args.workers}")
    _check_learner(args, domain)
    if args.backend not in BACKENDS:
        raise BadInput(f"unknown backend {args.backend!r}; expected one of {BACKENDS}")
    if args.ray_address is not None:
        if args.backend != "ray":
            raise BadInput("--ray-address needs --backend ray")
        check_ray_address(args.ray_address)
    return domain, agents, options, refresh, copies


def _check_learner(args, domain) -> None:
    if args.learner not in LEARNERS:
        raise BadInput(f"unknown learner {args.learner!r}; expected one of {LEARNERS}")
    if args.learner == "shared" and not on_copies(domain) and (args.workers or 0) > 1:
        raise BadInput(f"--learner shared is one network for every agent: --workers 1 (or 0), not {args.workers} "
                       "(each worker would train a network of its own agents)")


def on_copies(domain) -> bool:
    """Whether DIALS trains ``domain`` on copies of its multi-agent IALS ParallelEnv
    (:mod:`ials_zoo.baselines.dials_copies`: agents with spaces of their own) rather than on
    every agent's batched IALS."""
    return domain.has_ials_parallel_env and not domain.has_ials


def _check_copies_args(args) -> None:
    if args.local not in LOCAL_SIMULATORS:
        raise BadInput(f"--local: expected one of {', '.join(LOCAL_SIMULATORS)}, got {args.local!r}")
    if args.learner not in PPO_CLASSES:
        raise BadInput(f"--learner {args.learner}: agents with spaces of their own train with --learner batched or "
                       "shared (one torch program, observations padded)")
    if args.backend == "ray" and args.workers == 0:
        raise BadInput("--workers 0 with --backend ray: the IALS copies run in Ray actors, at least one")
    if args.aip == "shipped":
        raise BadInput(f"--aip shipped: no AIPs ship for {args.env_id}")


def default_workers(n_agents: int) -> int:
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(cores, n_agents))


class ShardsLearner(AIPRefreshes, JointActors):
    """The driver's adapter for DIALS: the agents split into shards (:mod:`ials_zoo.dials.shard`),
    each training its agents' PPO on their own IALS in a worker (``backend``), with the AIPs
    retrained on GS data from the joint policy at the refresh points (``refresh``)."""

    reports_aip_time = True

    def __init__(self, args: Args, domain, agents, options, refresh, copies, workers, ppo, frame_stack, updates,
                 training: dict, out: Path):
        self.args, self.out, self.domain, self.agents, self.options = args, out, domain, agents, options
        self.obs_size, self.n_actions = int(np.prod(domain.observation_space.shape)), domain.n_actions
        self.refresh = refresh
        self.copies, self.workers, self.ppo, self.frame_stack, self.updates = copies, workers, ppo, frame_stack, updates
        self.training, self.simulator = training, training["simulator"]
        self.aip_training = aip_training_of(args, domain)
        self.chunks = split_agents(agents, workers)
        self.charged_seconds, self.refreshes, self.aip_split = 0.0, 0, {"collect": 0.0, "train": 0.0}
        self.aips, self.state, self.backend = None, None, None

    def load(self, state, info):
        self.load_aips(state, info)
        self.state = state

    def start(self, steps):
        args = self.args
        specs = [ShardSpec(args.env_id, chunk, self.options, args.seed, self.copies, self.frame_stack, args.learner,
                           self.ppo, self.updates, {a: self.aips[a] for a in chunk}) for chunk in self.chunks]
        self.backend = (InProcessBackend(specs) if self.workers == 0
                        else make_backend(args.backend, specs, args.ray_address))
        if self.state is not None:
            by_agent = {a: s for s in self.state["shards"] for a in s["agents"]}
            self.backend.call("load_state", [(_shard_state(by_agent, c),) for c in self.chunks])
            self.state = None

    def actor_layers(self):
        per_shard = self.backend.call("actor_layers")
        return [tuple(np.concatenate([ls[i][j] for ls in per_shard]) for j in range(len(layer)))
                for i, layer in enumerate(per_shard[0])]

    def use_aips(self, aips: dict) -> None:
        self.backend.call("set_predictors", [(aips,)] * len(self.chunks))

    def train(self, steps, target, advance):
        stats = self.backend.call("train", [(target,)] * len(self.chunks))
        return dict(merge_shard_stats(stats, self.chunks), aip_refreshes=self.refreshes)

    def checkpoint(self, out):
        save_aips(out / "aips.pt", self.aips)
        shard_states = self.backend.call("state")
        return {"shards": [dict(s, agents=c) for s, c in zip(shard_states, self.chunks)]}, self.aip_info()

    def close(self):
        if self.backend is not None:
            self.backend.close()


def main(args: Args | None = None) -> dict:
    """Train with DIALS; returns the result dict (also written to result.json)."""
    args = args or Args()
    domain, agents, options, refresh, copies = check_args(args)
    torch.set_num_threads(1)
    per_update = args.samples_per_update
    total = whole_updates(int(args.total_timesteps or study_of(domain).multi_agent_budget), per_update)
    eval_every = int(args.eval_every or max(per_update, total // 10))
    one_network = args.learner == "shared" and not on_copies(domain)  # a shared network has one shard
    workers = default_workers(len(agents)) if args.workers is None else min(args.workers, len(agents))
    workers = 1 if one_network and args.workers is None else workers
    frame_stack = frame_stack_of(args, domain)
    out = Path(args.out_dir or f"runs/{args.env_id}__dials__s{args.seed}")
    ppo = ppo_config(args, copies, frame_stack)
    how = aip_training_of(args, domain)
    label = (_label(args.aip, refresh, how.autoregressive, args.aip_training) + ("-arrays" if args.local == "arrays" else "")
             + ("-shared" if args.learner == "shared" else ""))
    training = {"simulator": label, "aip": None, "seeds": [args.seed], "env_steps": 0,
                "wall_clock_seconds": 0.0, "aip_seconds": 0.0, "workers": max(workers, 1), "backend": args.backend,
                "hyperparameters": dict(settings_of(args), agents=agents, refresh_steps=refresh,
                                        total_timesteps=total, eval_every=eval_every,
                                        collect_steps=how.collect_steps, aip_epochs=how.epochs,
                                        aip_autoregressive=how.autoregressive, aip_lr=how.lr,
                                        aip_lr_schedule=how.lr_schedule, aip_influence_lags=how.influence_lags,
                                        aip_clock_horizon=how.clock_horizon,
                                        ppo=ppo,
                                        learner=args.learner)}
    plan = RunPlan("dials", args.env_id, agents, options, args.seed, total, per_update, eval_every, args.eval_episodes,
                   args.final_eval_episodes, frame_stack, out, settings_of(args), training, args.resume,
                   args.overwrite, args.progress, args.submitter, args.notes,
                   checkpoint_every=checkpoint_every_of(args, eval_every, per_update),
                   command=training_command("dials", args))
    if on_copies(domain):
        learner = IALSCopiesLearner(args, domain, agents, options, refresh, copies, max(workers, 0), ppo, frame_stack,
                                    total // per_update, joint_sizes(domain, agents, options), training, out)
        n = min(workers, copies)
        holders = (f"{n} Ray actor{'s' if n != 1 else ''}" if args.backend == "ray"
                   else f"{n} worker process{'es' if n != 1 else ''}")
        ppo_of = "one shared PPO" if args.learner == "shared" else "every agent's PPO"
        where = (f"{ppo_of}, every agent's IALS side by side, {copies} cop{'ies' if copies > 1 else 'y'} in {holders}"
                 + (", on arrays" if args.local == "arrays" else ""))
    else:
        learner = ShardsLearner(args, domain, agents, options, refresh, copies, workers, ppo, frame_stack,
                                total // per_update, training, out)
        where = f"{args.learner} PPO, {workers} worker{'s' if workers != 1 else ''}, {args.backend} backend"
    refresh_text = {None: "never", 0: "once, at the start"}.get(refresh) or f"every {refresh:,} steps"
    rounds = 0 if args.aip != "trained" or refresh is None else 1 + (0 if refresh == 0 else (total - 1) // refresh)
    collect = aip_training_of(args, domain).collect_steps
    rounds_text = (f"; {rounds} AIP round{'s' if rounds != 1 else ''} on the clock, each {collect:,} GS steps of "
                   "data and the AIPs' training (minutes each; the measured speed below leaves them out)") if rounds else ""
    return run(plan, learner, f"dials: {len(agents)} agents of {args.env_id} learn at once, each on its own IALS "
               f"({where}); AIPs: "
               f"{args.aip}, retrained {refresh_text}{rounds_text}", domain)


def _shard_state(by_agent: dict, chunk: list) -> dict:
    """The saved state of a shard holding ``chunk`` (a run resumes with the same split)."""
    state = by_agent.get(chunk[0])
    if state is None or state["agents"] != chunk:
        raise BadInput("resume with the same number of workers as the run had (its checkpoint is per worker)")
    return {k: v for k, v in state.items() if k != "agents"}


def _label(aip: str, refresh, autoregressive: bool = False, aip_training: str = "dials") -> str:
    """The simulator name a result carries."""
    if aip == "trained":
        kind = "-fidelity" if aip_training == "fidelity" else "-autoregressive" if autoregressive else ""
        return ("dials" if refresh else "dials-once") + kind
    if aip == "untrained":
        return "untrained-dials"
    return f"dials-{aip}" if not aip.endswith(".pt") else "dials-file"


if __name__ == "__main__":
    import sys

    sys.exit(run_cli(sys.modules[__name__]))
