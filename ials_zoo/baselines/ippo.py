"""IPPO on the GS: every agent learns in the one global simulator with its own policy.

Usage::

    ials-zoo train ippo --env traffic_grid_v0 --simulator gs
    python -m baselines.ippo --help

Every agent has its own actor, critic and PPO update (the settings of :mod:`.dials`, one
batched torch program, :mod:`ials_zoo.learners.batched_ppo`); the experience comes from
``--n-envs`` copies of the GS with every agent acting (no scripted agents), which run in
``--gs-processes`` worker processes (default: one per copy for a SUMO GS, none for a numpy
one) while the learner runs here. This is the reference DIALS is compared with: the same
agents, the same PPO, the same budget per agent, trained on the GS instead of on IALS.

Outputs in ``--out-dir`` as for :mod:`.dials` (``status.json``, ``progress.csv``,
``curve.json``, ``checkpoint.pt``/``.json``, ``policy.safetensors``, ``result.json`` on the
multi-agent track); wall-clock: training only (GS evaluations and checkpoints excluded).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ials_zoo.baselines.common import arg, parse_env_options, run_cli
from ials_zoo.baselines.multiagent import MultiPPOSettings


@dataclass
class Args(MultiPPOSettings):
    """Arguments of :func:`main` (``python -m baselines.ippo --help``)."""

    env_id: str | None = arg(None, "domain id (required)", aliases=("--env",))
    simulator: str = arg("gs", "gs (IPPO trains on the GS; for IALS use `train dials`)")
    agents: str = arg("all", "learning agents, comma-separated, or 'all'")
    seed: int = arg(0, "run seed")
    total_timesteps: int | None = arg(None, "environment steps per agent (default: the domain's multi-agent budget)")
    n_envs: int = arg(2, "GS copies")
    gs_processes: int | None = arg(None, "worker processes of the GS copies (default: one per copy for SUMO, else 0)")
    env_options: str = arg("", "domain options as a JSON object")
    eval_every: int | None = arg(None, "GS evaluation every N steps per agent (default: a tenth of the budget)")
    eval_episodes: int = arg(10, "GS episodes per evaluation")
    final_eval_episodes: int = arg(20, "GS episodes of the final score (the protocol's 20)")
    out_dir: str | None = arg(None, "output folder (default: runs/<env>__ippo__s<seed>)")
    resume: bool = arg(False, "continue the unfinished run in --out-dir from its last checkpoint")
    overwrite: bool = arg(False, "replace whatever --out-dir holds")
    progress: bool = arg(True, "show a progress bar")
    submitter: str = arg("", "submitter name for result.json")
    notes: str = arg("", "notes for result.json")


def main(args: Args | None = None) -> dict:
    """Train IPPO on the GS; returns the result dict (also written to result.json)."""
    import torch

    import ials_zoo
    from ials_zoo.baselines.common import format_seconds
    from ials_zoo.baselines.multiagent import (
        TrainingLog,
        check_multi_ppo,
        final_results,
        frame_stack_of,
        joint_policy,
        merge_shard_stats,
        policy_file,
        ppo_config,
        settings_of,
        whole_updates,
        write_curve,
    )
    from ials_zoo.baselines.runs import Clock, RunFolder, load_training_state, save_training_state
    from ials_zoo.core.domains import domain_ids, get_domain
    from ials_zoo.evaluation import evaluate_joint
    from ials_zoo.leaderboard import now_iso
    from ials_zoo.learners.batched_ppo import BatchedPPO, PPOConfig
    from ials_zoo.learners.gs_vec import GSVecEnv
    from ials_zoo.learners.rollout import RolloutTrainer
    from ials_zoo.utils import check_seed

    args = args or Args()
    if args.env_id is None:
        raise ValueError(f"name the domain to train on: --env, one of {', '.join(domain_ids())}")
    if args.simulator != "gs":
        raise ValueError(f"ippo trains on the GS (--simulator gs); every agent on its own IALS is `ials-zoo train "
                         f"dials`, not --simulator {args.simulator!r}")
    domain = get_domain(args.env_id)
    options = parse_env_options(args.env_options)
    agents = domain.check_agents(None if args.agents == "all" else args.agents, **options)
    check_seed(args.seed, "seed")
    check_multi_ppo(args)
    for name in ("n_envs", "eval_episodes", "final_eval_episodes"):
        if getattr(args, name) < 1:
            raise ValueError(f"{name} must be >= 1, got {getattr(args, name)}")
    for name in ("total_timesteps", "eval_every"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            raise ValueError(f"{name} must be >= 1, got {getattr(args, name)}")
    processes = (args.n_envs if domain.one_simulation_per_process else 0) if args.gs_processes is None else args.gs_processes
    if processes < 0:
        raise ValueError(f"gs_processes must be >= 0, got {processes}")
    torch.set_num_threads(1)
    ppo = ppo_config(args, args.n_envs)
    per_update = args.samples_per_update
    total = whole_updates(int(args.total_timesteps or domain.study.multi_agent_budget), per_update)
    eval_every = int(args.eval_every or max(per_update, total // 10))
    frame_stack = frame_stack_of(args, domain)
    obs_size = int(np.prod(domain.observation_space.shape))
    out = Path(args.out_dir or f"runs/{args.env_id}__ippo__s{args.seed}")
    run = RunFolder(out, resume=args.resume, overwrite=args.overwrite,
                    settings=settings_of(args, skip=("resume", "overwrite", "progress", "out_dir", "submitter", "notes",
                                                     "gs_processes")))
    print(f"ippo: {len(agents)} agents of {args.env_id} learn at once on the GS ({args.n_envs} GS cop"
          f"{'ies' if args.n_envs > 1 else 'y'}, {processes} worker process{'es' if processes != 1 else ''})\n"
          f"  {total:,} steps per agent; writing {out}/" + (" (resuming)" if run.resuming else ""), flush=True)
    meta = {"algorithm": "ippo", "env_id": args.env_id, "env_options": options, "seed": args.seed,
            "package_version": ials_zoo.__version__, "created": now_iso()}
    training = {"simulator": "gs", "aip": None, "seeds": [args.seed], "env_steps": 0, "wall_clock_seconds": 0.0,
                "aip_seconds": 0.0, "workers": max(processes, 1),
                "hyperparameters": dict(dataclasses.asdict(args), agents=agents, total_timesteps=total,
                                        eval_every=eval_every, ppo=ppo, gs_processes=processes)}
    with run.running():
        log = TrainingLog(out / "progress.csv")
        learner = BatchedPPO(agents, obs_size * frame_stack, domain.n_actions, PPOConfig(**ppo), args.seed,
                             total // per_update)
        steps, curve, clock_offset = 0, [], 0.0
        if run.resuming:
            state, info = load_training_state(out)
            learner.load_state_dict(state["learner"])
            steps, curve, clock_offset = int(info["steps"]), info["curve"], float(info["clock"])
        clock = Clock(offset=clock_offset)
        env = GSVecEnv(args.env_id, agents, args.n_envs, processes, seed=args.seed + 1000 * (steps // per_update),
                       **options)
        try:
            trainer = RolloutTrainer(learner, env, frame_stack)

            def policy_net():
                return joint_policy(agents, learner.actor_layers(), obs_size, domain.n_actions, frame_stack,
                                    dict(meta, training=training, learning_curve=curve))

            bar = None
            if args.progress:
                from tqdm.auto import tqdm

                bar = tqdm(total=total, initial=steps, unit="step/agent", dynamic_ncols=True, desc="ippo")
            next_eval = curve[-1]["env_steps"] + eval_every if curve else 0
            stats: list[dict] = []
            while True:
                if steps >= next_eval or steps >= total:
                    with clock.pause():
                        ev = evaluate_joint(args.env_id, policy_net(), episodes=args.eval_episodes, **options)
                        curve.append({"env_steps": steps, "wall_clock_seconds": clock.seconds, "mean": ev.mean,
                                      "ci_low": ev.ci_low, "ci_high": ev.ci_high})
                        write_curve(out, {"env_id": args.env_id, "algorithm": "ippo", "seed": args.seed,
                                          "simulator": "gs"}, curve)
                        save_training_state(out, {"learner": learner.state_dict()},
                                            {"steps": steps, "curve": curve, "clock": clock.seconds})
                    if stats:
                        row = merge_shard_stats([dict(_mean(stats), episode_returns=_returns(trainer))], [len(agents)])
                        log.add(dict(row, steps_per_agent=steps, wall_clock_seconds=round(clock.seconds, 3)))
                        stats = []
                    if bar is not None:
                        bar.set_postfix(gs=f"{ev.mean:.2f}")
                    next_eval = steps + eval_every
                if steps >= total:
                    break
                stats.append(trainer.collect_and_update())
                steps += per_update
                if bar is not None:
                    bar.update(per_update)
            if bar is not None:
                bar.close()
            training.update(env_steps=steps, wall_clock_seconds=clock.seconds)
            path = policy_file(out, policy_net())
        finally:
            env.close()
        result, deterministic = final_results(out, args.env_id, path, "ippo", training, curve, agents, args.seed,
                                              args.final_eval_episodes, options, args.submitter, args.notes,
                                              args.progress)
    s = result["score"]
    print(f"ippo: GS score (mean over {len(agents)} agents) {s['mean']:.3f} [{s['ci_low']:.3f}, {s['ci_high']:.3f}] "
          f"after {steps:,} steps per agent; wall-clock {format_seconds(training['wall_clock_seconds'])}; "
          f"deterministic {deterministic['score']['mean']:.3f}; wrote {out}/result.json", flush=True)
    return result


def _mean(stats: list[dict]) -> dict:
    return {k: float(np.mean([s[k] for s in stats])) for k in stats[0]}


def _returns(trainer):
    r = trainer.episode_returns()
    return None if r is None else [float(x) for x in r]


if __name__ == "__main__":
    import sys

    sys.exit(run_cli(sys.modules[__name__]))
