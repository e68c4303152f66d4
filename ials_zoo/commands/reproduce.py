"""``ials-zoo reproduce``: run the paper's experiments (resumable, with a step budget).

Examples::

    ials-zoo reproduce --dry-run
    ials-zoo reproduce --experiments training --domains warehouse_v0 --budget 300000 --seeds 3
    ials-zoo reproduce --report-only
    ials-zoo reproduce --experiments dials --seeds 3     # every agent learning: IPPO vs DIALS

Experiments: ``training`` (paper §5.2-5.3: PPO on gs / ials / untrained-ials / fixed:0.1
[/ marginal], GS-evaluated curves vs wall-clock incl. the AIP's measured collection +
training time), ``memory`` (§5.4: M-IALS vs NM-IALS x agents with/without frame stack,
item_lifetime=8, + item-lifetime histograms), ``dset`` (§4.2: d-set vs full-observation AIP,
off-policy cross-entropy), ``dials`` (SPEC §6, every agent learning at once: GS-IPPO, DIALS
with periodic refresh, DIALS with AIPs trained once, untrained-DIALS, the 1-worker repeat of
DIALS seed 0 for parallel efficiency, and joint scripted / random references; each multi-agent
run has the machine to itself). Each run is a subprocess writing into its own folder under
``--out``; a run whose marker (``result.json``) exists is skipped, so the study can be
continued across invocations. Afterwards the finished training runs are submitted to the
leaderboard and ``<leaderboard>/reproduction.md`` + curve PNGs are re-made.

Default budget: each domain's ``study_of(domain).budget`` (2,000,000 PPO steps per warehouse run,
the paper's; 300,000 per traffic run, paper: 2M, because the SUMO GS trains ~5x slower and its
curves are flat from ~100k steps) and 500,000 per memory-experiment run; see ``--budget``.
"""

from __future__ import annotations

from ials_zoo.core.domains import ials_domain_ids
from ials_zoo.core.extras import study_of
from ials_zoo.errors import BadInput
from ials_zoo.reproduce import build_plan, describe_plan, settings
from ials_zoo.reproduce.plan import (
    DEFAULT_DIALS_VARIANTS,
    DEFAULT_MEMORY_BUDGET,
    DEFAULT_SIMULATORS,
    DIALS_VARIANTS,
    EXPERIMENTS,
    Config,
    default_budgets,
)
from ials_zoo.reproduce.report import submit_results, write_report
from ials_zoo.reproduce.runner import run_jobs


def _csv(text: str) -> tuple:
    return tuple(x.strip() for x in str(text).split(",") if x.strip())


def configure(parser):

    c = Config()
    parser.add_argument("--experiments", default=",".join(EXPERIMENTS),
                        help=f"comma-separated, some of {','.join(EXPERIMENTS)} (default: all)")
    parser.add_argument("--domains", default=",".join(ials_domain_ids()), help="comma-separated domain ids (default: all)")
    parser.add_argument("--agents", default="",
                        help="learning agents, e.g. tls_12,tls_18 (default: robot_20 and tls_12)")
    parser.add_argument("--simulators", default=",".join(DEFAULT_SIMULATORS),
                        help="training simulators of the 'training' experiment (gs required; 'marginal' optional)")
    parser.add_argument("--budget", default=None,
                        help="PPO environment steps per run: N for every domain, and/or DOMAIN=N pairs, "
                             "e.g. 200000 or warehouse_v0=1000000,traffic_grid_v0=300000 (default: "
                             + ", ".join(f"{d}={b}" for d, b in default_budgets().items()) + ")")
    parser.add_argument("--memory-budget", type=int, default=None,
                        help="PPO environment steps per run of the memory experiment (12 warehouse runs; "
                             f"default {DEFAULT_MEMORY_BUDGET}, or the warehouse's budget when --budget is given)")
    parser.add_argument("--dials-budget", default=None,
                        help="steps per agent of each multi-agent run: N, and/or DOMAIN=N pairs (default: "
                             + ", ".join(f"{d}={study_of(d).multi_agent_budget}" for d in ials_domain_ids()) + ")")
    parser.add_argument("--dials-variants", default=",".join(DEFAULT_DIALS_VARIANTS),
                        help=f"multi-agent runs of the dials experiment, some of {','.join(DIALS_VARIANTS)} "
                             f"(default: all but {','.join(v for v in DIALS_VARIANTS if v not in DEFAULT_DIALS_VARIANTS)})")
    parser.add_argument("--dials-workers", type=int, default=c.dials_workers,
                        help="worker processes of each DIALS run (default 2 = cores; with more than 1, the "
                             "periodic run of seed 0 is repeated on 1 worker for the parallel efficiency)")
    parser.add_argument("--seeds", type=int, default=c.seeds, help="training seeds per configuration")
    parser.add_argument("--jobs", type=int, default=c.jobs, help="runs at once (default 2 = cores)")
    parser.add_argument("--out", default=c.out, help="study folder")
    parser.add_argument("--leaderboard", default=c.leaderboard, help="leaderboard folder (figures, reproduction.md)")
    parser.add_argument("--net-arch", default=c.net_arch, help="PPO hidden layers")
    parser.add_argument("--n-envs", type=int, default=c.n_envs, help="parallel envs per PPO run")
    parser.add_argument("--eval-points", type=int, default=c.eval_points, help="GS evaluations per curve")
    parser.add_argument("--eval-episodes", type=int, default=c.eval_episodes, help="GS episodes per curve point")
    parser.add_argument("--final-eval-episodes", type=int, default=c.final_eval_episodes,
                        help="GS episodes of each run's final score (result.json)")
    parser.add_argument("--aip-steps", type=int, default=c.aip_steps, help="Algorithm 1 steps per AIP")
    parser.add_argument("--aip-epochs", type=int, default=None, help="AIP epochs (default: the project's)")
    parser.add_argument("--collect-workers", type=int, default=c.collect_workers,
                        help="GS processes collecting each traffic AIP's data (Algorithm 1)")
    parser.add_argument("--dset-offpolicy-steps", type=int, default=c.dset_offpolicy_steps,
                        help="steps of each off-policy test set of the d-set ablation")
    parser.add_argument("--lifetime-episodes", type=int, default=c.lifetime_episodes,
                        help="episodes per simulator of the item-lifetime histograms")
    parser.add_argument("--dry-run", action="store_true", help="print the plan (done/todo) and exit")
    parser.add_argument("--report-only", action="store_true",
                        help="run nothing: re-make figures, reproduction.md and submissions from the run folders")
    parser.add_argument("--no-submit", action="store_true", help="do not submit results to the leaderboard")
    parser.add_argument("--no-progress", action="store_true")


def parse_budget(text, default: int, default_domains: dict) -> tuple[int, dict]:
    """``--budget`` -> ``(budget, domain_budgets)``: None gives the defaults; ``"N"`` gives N
    for every domain; ``"DOMAIN=N,..."`` overrides those domains only (others keep the
    defaults); ``"N,DOMAIN=M"`` gives N everywhere except M for DOMAIN."""
    if text is None:
        return default, dict(default_domains)
    parts = _csv(text)
    plain = [p for p in parts if "=" not in p]
    budget, per = default, ({} if plain else dict(default_domains))
    for part in parts:
        key, sep, value = part.rpartition("=")
        try:
            steps = int(value.replace("_", ""))
        except ValueError:
            raise BadInput(f"--budget {text!r}: {part!r} is not N or DOMAIN=N with N an int") from None
        if sep:
            per[key] = steps
        else:
            budget = steps
    return budget, per


def config_from_args(args):
    """The :class:`~ials_zoo.reproduce.plan.Config` of parsed command-line ``args``."""

    budget, per = parse_budget(args.budget, Config.budget, default_budgets())
    dials_default, dials_per = parse_budget(args.dials_budget, 0, {})
    if dials_default:  # one N for every domain
        dials_per = {d: dials_per.get(d, dials_default) for d in _csv(args.domains)}
    memory_budget = args.memory_budget
    if memory_budget is None and args.budget is None:
        memory_budget = DEFAULT_MEMORY_BUDGET
    return Config(
        experiments=_csv(args.experiments), domains=_csv(args.domains), agents=_csv(args.agents),
        simulators=_csv(args.simulators), budget=budget, domain_budgets=per, memory_budget=memory_budget,
        seeds=args.seeds, jobs=args.jobs,
        out=args.out, leaderboard=args.leaderboard, net_arch=args.net_arch, n_envs=args.n_envs,
        eval_points=args.eval_points, eval_episodes=args.eval_episodes,
        final_eval_episodes=args.final_eval_episodes, aip_steps=args.aip_steps, aip_epochs=args.aip_epochs,
        collect_workers=args.collect_workers,
        dset_offpolicy_steps=args.dset_offpolicy_steps, lifetime_episodes=args.lifetime_episodes,
        dials_variants=_csv(args.dials_variants), dials_budgets=dials_per, dials_workers=args.dials_workers,
    ).check()


def run(args) -> int:

    cfg = config_from_args(args)  # bad settings raise BadInput: one line, exit 2
    jobs = build_plan(cfg)
    if args.dry_run:
        print(describe_plan(jobs))
        return 0
    status = {"failed": [], "blocked": []}
    if not args.report_only:
        status = run_jobs(jobs, n_jobs=cfg.jobs, progress=not args.no_progress, lock_dir=cfg.out)
        print(f"jobs: {len(status['done'])} run, {len(status['skipped'])} already done, "
              f"{len(status['failed'])} failed, {len(status['blocked'])} blocked")
        for jid in status["failed"]:
            print(f"  failed: {jid}")
    if not args.no_submit:
        sub = submit_results(cfg.out, cfg.leaderboard)
        print(f"leaderboard: {len(sub['submitted'])} submitted, {len(sub['already'])} already there, "
              f"{len(sub['rejected'])} rejected, {len(sub['incomplete'])} waiting for seeds still to run")
        for r in sub["rejected"]:
            print(f"  rejected: {r}")
    # --report-only: the settings of this command line need not be those of the runs.
    path = write_report(cfg.out, cfg.leaderboard, None if args.report_only else settings(cfg),
                        cfg.experiments)
    print(f"wrote {path}")
    return 1 if status["failed"] or status["blocked"] else 0
