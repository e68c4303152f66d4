"""DIALS: every agent learns at once, each on its own IALS, spread over workers (SPEC §6).

Usage::

    ials-zoo train dials --env traffic_grid_v0                       # periodic AIP refresh
    ials-zoo train dials --env warehouse_v0 --refresh once           # AIPs trained once, at the start
    ials-zoo train dials --env traffic_grid_v0 --aip untrained --refresh never   # untrained-DIALS
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

``--aip``: ``trained`` (collected and trained at step 0, timed), ``untrained`` (random
networks), ``uniform``, ``fixed:P``, ``shipped`` (the AIPs that ship with the package; their
recorded collection and training time is charged) or a predictor-set file.

**Learners**: ``--learner batched`` (default: every agent's PPO in one torch program,
:mod:`ials_zoo.learners.batched_ppo`) or ``sb3`` (one stable-baselines3 PPO per agent, the
reference). **Determinism**: everything an agent does depends only on the run seed and its
name, not on its worker: the same seed gives the same run on either backend and with any
``--workers`` (bitwise on this CPU and torch build; see :mod:`ials_zoo.learners.batched_ppo`).

**Wall-clock** (``training.wall_clock_seconds``): training, plus the AIPs' data collection and
training (``training.aip_seconds``, included in the curve as in the paper's plots); GS
evaluations and checkpoints excluded. Outputs in ``--out-dir`` as for the other baselines
(:mod:`ials_zoo.baselines.runs`): ``status.json``, ``progress.csv``, ``curve.json``,
``checkpoint.pt``/``checkpoint.json`` + ``aips.pt`` (every round: ``--resume`` continues a
killed run), ``policy.safetensors`` (the joint policy) and ``result.json`` (multi-agent track).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ials_zoo.baselines.common import arg, parse_env_options, run_cli
from ials_zoo.baselines.multiagent import MultiPPOSettings

REFRESH_WORDS = ("default", "once", "never")


def _per_domain(describe) -> str:
    """``"<env_id> <what>, ..."`` for every known domain (help texts read from the data)."""
    from ials_zoo.core.domains import domain_ids, get_domain

    return ", ".join(f"{env_id} {describe(get_domain(env_id))}" for env_id in domain_ids())


def _refresh_text(domain) -> str:
    refresh = domain.dials.refresh
    return "once" if refresh == 0 else "never" if refresh is None else f"every {refresh:,}"


@dataclass
class Args(MultiPPOSettings):
    """Arguments of :func:`main` (``python -m baselines.dials --help``)."""

    env_id: str | None = arg(None, "domain id (required)", aliases=("--env",))
    agents: str = arg("all", "learning agents, comma-separated, or 'all'")
    seed: int = arg(0, "run seed")
    total_timesteps: int | None = arg(None, "environment steps per agent (default: the domain's multi-agent budget)")
    refresh: str = arg("default", lambda: "retrain the AIPs every N steps per agent, 'once' (at the start), 'never', "
                       f"or 'default' (the domain's: {_per_domain(_refresh_text)})")
    aip: str = arg("trained", "initial AIPs: trained | untrained | uniform | fixed:P | shipped | FILE.pt")
    collect_steps: int | None = arg(None, lambda: "GS steps per data collection (default: the domain's: "
                                    f"{_per_domain(lambda d: f'{d.dials.collect_steps:,}')})")
    aip_epochs: int | None = arg(None, "epochs per AIP (re)training (default: the domain's)")
    n_envs: int | None = arg(None, lambda: f"IALS copies per agent (default: the domain's: "
                             f"{_per_domain(lambda d: str(d.dials.copies))})")
    learner: str = arg("batched", "batched (one torch program) | sb3 (one SB3 PPO per agent)")
    workers: int | None = arg(None, "worker processes (default: one per core; 0: this process)")
    backend: str = arg("process", "process | ray")
    ray_address: str | None = arg(None, "an existing Ray cluster (host:port); default: a local Ray")
    env_options: str = arg("", "domain options as a JSON object")
    eval_every: int | None = arg(None, "GS evaluation every N steps per agent (default: a tenth of the budget)")
    eval_episodes: int = arg(10, "GS episodes per evaluation")
    final_eval_episodes: int = arg(20, "GS episodes of the final score (the protocol's 20)")
    out_dir: str | None = arg(None, "output folder (default: runs/<env>__dials__s<seed>)")
    resume: bool = arg(False, "continue the unfinished run in --out-dir from its last checkpoint")
    overwrite: bool = arg(False, "replace whatever --out-dir holds")
    progress: bool = arg(True, "show a progress bar")
    submitter: str = arg("", "submitter name for result.json")
    notes: str = arg("", "notes for result.json")


def parse_refresh(text: str, default: int) -> int | None:
    """Steps per agent between AIP refreshes; 0: once, at the start; None: never."""
    t = str(text).strip().lower()
    if t == "default":
        return default
    if t == "once":
        return 0
    if t == "never":
        return None
    try:
        n = int(t.replace("_", ""))
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"--refresh {text!r}: expected a number of steps >= 1, 'once', 'never' or 'default'")
    return n


def check_args(args: Args):
    """Clear errors before anything starts; returns (domain, agents, options, refresh, copies)."""
    from ials_zoo.baselines.multiagent import check_multi_ppo, ppo_config
    from ials_zoo.core.domains import domain_ids, get_domain
    from ials_zoo.dials.backends import BACKENDS, check_ray_address
    from ials_zoo.dials.shard import LEARNERS
    from ials_zoo.influence.specs import parse_predictor
    from ials_zoo.utils import check_seed

    if args.env_id is None:
        raise ValueError(f"name the domain to train on: --env, one of {', '.join(domain_ids())}")
    domain = get_domain(args.env_id)
    options = parse_env_options(args.env_options)
    agents = domain.check_agents(None if args.agents == "all" else args.agents, **options)
    check_seed(args.seed, "seed")
    check_multi_ppo(args)
    refresh = parse_refresh(args.refresh, domain.dials.refresh)
    if args.aip == "shipped":
        from ials_zoo.influence.multi import shipped_set_path

        if not shipped_set_path(args.env_id).is_file():
            raise ValueError(f"--aip shipped: no AIPs ship for {args.env_id}")
        if refresh is not None:
            raise ValueError("--aip shipped is a fixed AIP set: use --refresh never (retraining would replace it)")
    else:
        spec = parse_predictor(args.aip)
        if spec.kind == "file" and not os.path.isfile(spec.path):
            raise ValueError(f"--aip {args.aip!r}: file not found")
        if spec.kind not in ("trained", "file") and refresh is not None:
            raise ValueError(f"--aip {args.aip} is a fixed AIP: use --refresh never (retraining would replace it)")
    for name in ("eval_episodes", "final_eval_episodes"):
        if getattr(args, name) < 1:
            raise ValueError(f"{name} must be >= 1, got {getattr(args, name)}")
    for name in ("n_envs", "total_timesteps", "collect_steps", "aip_epochs", "eval_every"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise ValueError(f"{name} must be >= 1, got {v}")
    copies = int(args.n_envs or domain.dials.copies)
    ppo_config(args, copies)
    if args.workers is not None and args.workers < 0:
        raise ValueError(f"workers must be >= 0, got {args.workers}")
    if args.learner not in LEARNERS:
        raise ValueError(f"unknown learner {args.learner!r}; expected one of {LEARNERS}")
    if args.backend not in BACKENDS:
        raise ValueError(f"unknown backend {args.backend!r}; expected one of {BACKENDS}")
    if args.ray_address is not None:
        if args.backend != "ray":
            raise ValueError("--ray-address needs --backend ray")
        check_ray_address(args.ray_address)
    return domain, agents, options, refresh, copies


def default_workers(n_agents: int) -> int:
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(cores, n_agents))


def initial_aips(args, env_id, agents, options, seed) -> tuple[dict, float]:
    """``({agent: AIP}, seconds to charge)`` before round 0's collection (if any)."""
    from ials_zoo.influence.multi import resolve_predictor_set, shipped_set_path

    if args.aip in ("trained", "untrained"):  # "trained": replaced by round 0's AIPs
        preds = resolve_predictor_set("untrained", env_id, agents, seed=seed, options=options)
        return dict(zip(agents, preds)), 0.0
    if args.aip == "shipped":
        preds = resolve_predictor_set(str(shipped_set_path(env_id)), env_id, agents, options=options)
        cost = max((p.metadata.get("dataset", {}).get("collect_seconds") or 0.0) + (p.metadata.get("train_seconds") or 0.0)
                   for p in preds)
        return dict(zip(agents, preds)), float(cost)
    preds = resolve_predictor_set(args.aip, env_id, agents, seed=seed, options=options)
    return dict(zip(agents, preds)), 0.0


def refresh_aips(env_id, agents, options, net, seed, steps, domain, epochs, old, progress, collect_workers=1):
    """Collect every region's data with the joint policy ``net`` (None: uniform random) and
    retrain every AIP (warm start from ``old`` when it holds networks of the same shape)."""
    from ials_zoo.baselines.multiagent import JointActor
    from ials_zoo.influence.dataset import collect_all
    from ials_zoo.influence.networks import ARCHS
    from ials_zoo.influence.train import train_predictors

    d = domain.dials
    policy = None if net is None else JointActor(net, seed)
    t0 = time.perf_counter()
    data = collect_all(env_id, agents, steps=steps, policy=policy, seed=seed, gs_options=options, progress=progress,
                       workers=collect_workers)
    collect_seconds = time.perf_counter() - t0
    warm = {a: p for a, p in old.items() if isinstance(p, ARCHS[d.aip_arch]) and p.hidden == d.aip_hidden
            and p.metadata.get("variant") == "trained"}
    t0 = time.perf_counter()
    preds, report = train_predictors(data, d.aip_arch, hidden=d.aip_hidden, lr=d.aip_lr, epochs=epochs,
                                     batch_size=d.aip_batch, seed=seed, init=warm or None, progress=progress)
    train_seconds = time.perf_counter() - t0
    return preds, {"collect_seconds": collect_seconds, "train_seconds": train_seconds,
                   "mean_test_cross_entropy": report["mean_test_cross_entropy"], "warm_start": bool(warm)}


def main(args: Args | None = None) -> dict:
    """Train with DIALS; returns the result dict (also written to result.json)."""
    import torch

    import ials_zoo
    from ials_zoo.baselines.common import format_seconds
    from ials_zoo.baselines.multiagent import (
        TrainingLog,
        final_results,
        frame_stack_of,
        joint_policy,
        merge_shard_stats,
        policy_file,
        ppo_config,
        save_aips,
        settings_of,
        whole_updates,
        write_curve,
    )
    from ials_zoo.baselines.runs import Clock, RunFolder, load_training_state, save_training_state
    from ials_zoo.dials.backends import InProcessBackend, make_backend
    from ials_zoo.dials.shard import ShardSpec, split_agents
    from ials_zoo.evaluation import evaluate_joint
    from ials_zoo.leaderboard import now_iso

    args = args or Args()
    domain, agents, options, refresh, copies = check_args(args)
    torch.set_num_threads(1)
    total = int(args.total_timesteps or domain.study.multi_agent_budget)
    per_update = args.samples_per_update
    total = whole_updates(total, per_update)
    eval_every = int(args.eval_every or max(per_update, total // 10))
    collect_steps = int(args.collect_steps or domain.dials.collect_steps)
    epochs = int(args.aip_epochs or domain.dials.aip_epochs)
    workers = default_workers(len(agents)) if args.workers is None else min(args.workers, len(agents))
    frame_stack = frame_stack_of(args, domain)
    obs_size = int(np.prod(domain.observation_space.shape))
    out = Path(args.out_dir or f"runs/{args.env_id}__dials__s{args.seed}")
    run = RunFolder(out, resume=args.resume, overwrite=args.overwrite, settings=settings_of(args))
    ppo = ppo_config(args, copies)
    refresh_text = {None: "never", 0: "once, at the start"}.get(refresh) or f"every {refresh:,} steps"
    print(f"dials: {len(agents)} agents of {args.env_id} learn at once, each on its own IALS "
          f"({args.learner} PPO, {workers} worker{'s' if workers != 1 else ''}, {args.backend} backend); AIPs: "
          f"{args.aip}, retrained {refresh_text}\n  {total:,} steps per agent; writing {out}/"
          + (" (resuming)" if run.resuming else ""), flush=True)

    meta = {"algorithm": "dials", "env_id": args.env_id, "env_options": options, "seed": args.seed,
            "package_version": ials_zoo.__version__, "created": now_iso()}
    training = {"simulator": _label(args.aip, refresh), "aip": None, "seeds": [args.seed], "env_steps": 0,
                "wall_clock_seconds": 0.0, "aip_seconds": 0.0, "workers": max(workers, 1), "backend": args.backend,
                "hyperparameters": dict(settings_of(args), agents=agents, refresh_steps=refresh,
                                        total_timesteps=total, eval_every=eval_every, collect_steps=collect_steps,
                                        aip_epochs=epochs, ppo=ppo, learner=args.learner)}
    with run.running():
        log = TrainingLog(out / "progress.csv")
        steps, curve, aip_seconds, refreshes, clock_offset = 0, [], 0.0, 0, 0.0
        aip_split = {"collect": 0.0, "train": 0.0}
        if run.resuming:
            state, info = load_training_state(out)
            from ials_zoo.influence.files import load_predictor_set

            aips = load_predictor_set(out / "aips.pt", env_id=args.env_id)
            steps, curve = int(info["steps"]), info["curve"]
            aip_seconds, refreshes, clock_offset = float(info["aip_seconds"]), int(info["refreshes"]), float(info["clock"])
            aip_split = info.get("aip_split", aip_split)
            training["aip"] = info.get("aip")
        else:
            aips, aip_seconds = initial_aips(args, args.env_id, agents, options, args.seed)
            state = None
            if args.aip != "trained":
                training["aip"] = _fixed_aip_record(args.aip, args.env_id, aips, aip_seconds)
        # AIP time spent in this process is on the clock as it runs; a shipped set's is charged
        clock = Clock(offset=clock_offset if run.resuming else aip_seconds)
        chunks = split_agents(agents, workers)
        specs = [ShardSpec(args.env_id, chunk, options, args.seed, copies, frame_stack, args.learner, ppo,
                           total // per_update, {a: aips[a] for a in chunk}) for chunk in chunks]
        backend = InProcessBackend(specs) if workers == 0 else make_backend(args.backend, specs, args.ray_address)
        try:
            if state is not None:
                by_agent = {a: s for s in state["shards"] for a in s["agents"]}
                backend.call("load_state", [(_shard_state(by_agent, c),) for c in chunks])

            def policy_net():
                layers_per_shard = backend.call("actor_layers")
                layers = [(np.concatenate([ls[i][0] for ls in layers_per_shard]),
                           np.concatenate([ls[i][1] for ls in layers_per_shard])) for i in range(len(layers_per_shard[0]))]
                return joint_policy(agents, layers, obs_size, domain.n_actions, frame_stack,
                                    dict(meta, training=training, learning_curve=curve))

            def evaluate(n_episodes, progress=False, net=None):
                with clock.pause():
                    return evaluate_joint(args.env_id, net or policy_net(), episodes=n_episodes, progress=progress,
                                          **options)

            def checkpoint():
                with clock.pause():
                    save_aips(out / "aips.pt", aips)
                    shard_states = backend.call("state")
                    save_training_state(out, {"shards": [dict(s, agents=c) for s, c in zip(shard_states, chunks)]},
                                        {"steps": steps, "curve": curve, "aip_seconds": aip_seconds,
                                         "refreshes": refreshes, "clock": clock.seconds, "aip_split": aip_split,
                                         "aip": training["aip"]})

            bar = None
            if args.progress:
                from tqdm.auto import tqdm

                bar = tqdm(total=total, initial=steps, unit="step/agent", dynamic_ncols=True, desc="dials")
            next_eval = curve[-1]["env_steps"] + eval_every if curve else 0

            def next_refresh():
                """Steps per agent at which the AIPs are next retrained (None: never again)."""
                if args.aip != "trained" or refresh is None:
                    return None
                if refreshes == 0:
                    return 0
                return refreshes * refresh if refresh > 0 else None

            while True:
                due = next_refresh()
                if due is not None and due <= steps < total:
                    net = policy_net() if steps > 0 else None
                    if bar is not None:
                        bar.set_postfix_str(f"AIP round {refreshes}: GS collection + training")
                    print(f"dials: AIP round {refreshes} at {steps:,} steps per agent: {collect_steps:,} GS steps of "
                          f"{'the joint policy' if net else 'uniformly random agents'}, then {len(agents)} "
                          f"{domain.dials.aip_arch.upper()} AIPs x {epochs} epochs ...", flush=True)
                    aips, rep = refresh_aips(args.env_id, agents, options, net, args.seed + refreshes, collect_steps,
                                             domain, epochs, aips, progress=False)
                    print(f"dials: AIP round {refreshes} done: collection {rep['collect_seconds']:.0f} s, training "
                          f"{rep['train_seconds']:.0f} s, mean test cross-entropy {rep['mean_test_cross_entropy']:.3f}",
                          flush=True)
                    aip_seconds += rep["collect_seconds"] + rep["train_seconds"]
                    aip_split["collect"] += rep["collect_seconds"]
                    aip_split["train"] += rep["train_seconds"]
                    backend.call("set_predictors", [(aips,)] * len(chunks))
                    refreshes += 1
                    training["aip"] = {"variant": "trained", "file": None, "sha256": None,
                                       "collection_seconds": aip_split["collect"],
                                       "training_seconds": aip_split["train"], "refreshes": refreshes,
                                       "last": dict(rep, at_steps_per_agent=steps)}
                if steps >= next_eval or steps >= total:
                    ev = evaluate(args.eval_episodes)
                    curve.append({"env_steps": steps, "wall_clock_seconds": clock.seconds, "mean": ev.mean,
                                  "ci_low": ev.ci_low, "ci_high": ev.ci_high})
                    write_curve(out, {"env_id": args.env_id, "algorithm": "dials", "seed": args.seed,
                                      "simulator": training["simulator"]}, curve)
                    checkpoint()
                    if bar is not None:
                        bar.set_postfix(gs=f"{ev.mean:.2f}")
                    next_eval = steps + eval_every
                if steps >= total:
                    break
                target = min(total, next_eval)
                nr = next_refresh()
                if nr is not None and nr > steps:
                    target = min(target, nr)
                target = max(steps + per_update, target // per_update * per_update)
                stats = backend.call("train", [(target,)] * len(chunks))
                steps = target
                row = merge_shard_stats(stats, [len(c) for c in chunks])
                log.add(dict(row, steps_per_agent=steps, wall_clock_seconds=round(clock.seconds, 3),
                             aip_refreshes=refreshes))
                if bar is not None:
                    bar.update(steps - bar.n)
            if bar is not None:
                bar.close()
            training.update(env_steps=steps, wall_clock_seconds=clock.seconds - aip_seconds, aip_seconds=aip_seconds)
            net = policy_net()
            path = policy_file(out, net)
        finally:
            backend.close()
        result, deterministic = final_results(out, args.env_id, path, "dials", training, curve, agents, args.seed,
                                              args.final_eval_episodes, options, args.submitter, args.notes,
                                              args.progress)
    s = result["score"]
    print(f"dials: GS score (mean over {len(agents)} agents) {s['mean']:.3f} [{s['ci_low']:.3f}, {s['ci_high']:.3f}] "
          f"after {steps:,} steps per agent; wall-clock {format_seconds(training['wall_clock_seconds'] + aip_seconds)} "
          f"(of which AIP collection and training {format_seconds(aip_seconds)}); deterministic "
          f"{deterministic['score']['mean']:.3f}; wrote {out}/result.json", flush=True)
    return result


def _fixed_aip_record(aip: str, env_id: str, aips: dict, charged: float) -> dict:
    """``training.aip`` of AIPs that DIALS does not train (untrained, fixed, shipped, a file)."""
    from ials_zoo.evaluation import sha256_file
    from ials_zoo.influence.multi import shipped_set_path

    path = shipped_set_path(env_id) if aip == "shipped" else (aip if aip.endswith(".pt") else None)
    first = next(iter(aips.values()))
    collect = max(float(p.metadata.get("dataset", {}).get("collect_seconds") or 0.0) for p in aips.values())
    return {"variant": first.metadata.get("variant", aip) if path else aip, "file": None if path is None else str(path),
            "sha256": None if path is None else sha256_file(path),
            "collection_seconds": collect if charged else 0.0,
            "training_seconds": max(charged - collect, 0.0) if charged else 0.0, "refreshes": 0}


def _shard_state(by_agent: dict, chunk: list) -> dict:
    """The saved state of a shard holding ``chunk`` (a run resumes with the same split)."""
    state = by_agent.get(chunk[0])
    if state is None or state["agents"] != chunk:
        raise ValueError("resume with the same number of workers as the run had (its checkpoint is per worker)")
    return {k: v for k, v in state.items() if k != "agents"}


def _label(aip: str, refresh) -> str:
    """The simulator name a result carries."""
    if aip == "trained":
        return "dials" if refresh else "dials-once"
    if aip == "untrained":
        return "untrained-dials"
    return f"dials-{aip}" if not aip.endswith(".pt") else "dials-file"


if __name__ == "__main__":
    import sys

    sys.exit(run_cli(sys.modules[__name__]))
