"""``ials-zoo train-aip``: train an approximate influence predictor (paper §4.2).

Examples::

    ials-zoo train-aip --data wh.npz --arch gru --out robot_20.pt
    ials-zoo train-aip --env traffic_grid_v0 --agent tls_12 --steps 50000 --arch mlp --out t12.pt
    ials-zoo train-aip --env warehouse_v0 --agent all --steps 50000 --out robots.pt
    ials-zoo train-aip --env warehouse_v0 --agent all --steps 50000 --autoregressive --out robots_ar.pt

Without ``--data`` it first collects ``--steps`` steps (Algorithm 1). Several agents (a
comma-separated list, or ``all``): one GS run records every listed region (all of them acting
uniformly at random) and every agent's AIP is trained at once with the domain's multi-agent
(DIALS) settings unless given, into one predictor-set file (what ``make_ials_parallel_env`` and
``train dials --aip FILE`` read). One agent: prints the train/test
cross-entropy (nats, mean over influence sources) of the trained AIP against the untrained
variants (random initialisation, uniform probabilities) and the empirical marginal, and the
collection/training wall-clock times. ``--report`` also writes them as JSON.
"""

from __future__ import annotations

import json
import math

from ials_zoo.commands import CommandError
from ials_zoo.commands.collect import add_collect_arguments, check_collect_arguments
from ials_zoo.core.domains import get_domain
from ials_zoo.core.extras import dials_of
from ials_zoo.evaluation import estimate_evaluation_seconds
from ials_zoo.influence.dataset import InfluenceDataset, collect, collect_all
from ials_zoo.influence.files import save_predictor, save_predictor_set
from ials_zoo.influence.train import LR_SCHEDULES, format_report, train_predictor, train_predictors
from ials_zoo.utils import atomic_write_text, check_output_file, format_seconds


def configure(parser):
    parser.add_argument("--data", default=None, help="an .npz data set from `ials-zoo collect`")
    add_collect_arguments(parser, required=False)
    parser.add_argument("--arch", choices=["gru", "mlp"], default=None,
                        help="AIP architecture (default: the domain's, gru for the warehouse, mlp for traffic)")
    parser.add_argument("--dset-kind", choices=["dset", "full"], default="dset",
                        help="d-set the AIP reads: the paper's minimal d-set or the full observation")
    parser.add_argument("--epochs", type=int, default=None)
    parser.add_argument("--lr", type=float, default=None)
    parser.add_argument("--lr-schedule", default=None,
                        help="linear or constant: the learning rate over training, linear decay to 0 (default for one agent) or "
                             "constant (the default of a set with the domain's DIALS architecture, as DIALS trains)")
    parser.add_argument("--hidden", type=int, default=None, help="hidden units of the AIP network")
    parser.add_argument("--batch-size", type=int, default=None,
                        help="episodes per batch (gru) or steps per batch (mlp)")
    parser.add_argument("--autoregressive", action="store_true",
                        help="an AIP that also reads the influence of the previous step, P(u_t | d_<=t, u_<t)")
    parser.add_argument("--influence-lags", type=int, default=None,
                        help="with --autoregressive: how many past steps of its influence the AIP reads (default 1)")
    parser.add_argument("--save-data", default=None, help="also save the collected data here")
    parser.add_argument("--report", default=None, help="write the training report as JSON here")
    parser.add_argument("--out", required=True, help="output predictor file (.pt)")


def check_training_arguments(args) -> None:
    if args.epochs is not None and args.epochs < 1:
        raise CommandError(f"--epochs must be >= 1 (0 epochs would label an untrained network 'trained'), "
                           f"got {args.epochs}")
    if args.lr is not None and not (math.isfinite(args.lr) and args.lr > 0):
        raise CommandError(f"--lr must be a finite number > 0, got {args.lr}")
    if args.batch_size is not None and args.batch_size < 1:
        raise CommandError(f"--batch-size must be >= 1, got {args.batch_size}")
    if args.lr_schedule is not None and args.lr_schedule not in LR_SCHEDULES:
        raise CommandError(f"--lr-schedule must be one of {', '.join(LR_SCHEDULES)}, got {args.lr_schedule!r}")
    if args.hidden is not None and args.hidden < 1:
        raise CommandError(f"--hidden must be >= 1, got {args.hidden}")
    lags = getattr(args, "influence_lags", None)
    if lags is not None and (lags < 1 or not args.autoregressive):
        raise CommandError(f"--influence-lags must be >= 1 and needs --autoregressive, got {lags}"
                           f"{'' if args.autoregressive else ' without --autoregressive'}")


def run(args) -> int:
    import torch


    check_training_arguments(args)
    check_output_file(args.out, "--out")
    for path, option in ((args.report, "--report"), (args.save_data, "--save-data")):
        if path:
            check_output_file(path, option)
    torch.set_num_threads(1)
    progress = not args.no_progress
    if args.agent is not None and (args.agent == "all" or "," in args.agent):
        return _train_set(args, progress)
    if args.data:
        if args.net is not None:
            raise CommandError("--net names a network to collect on; --data holds data already collected (drop one)")
        data = InfluenceDataset.load(args.data, env_id=args.env, agent=args.agent)
    else:
        if not (args.env and args.agent):
            raise CommandError("give --data FILE, or --env and --agent to collect data")
        options = check_collect_arguments(args)
        data = collect(args.env, args.agent, steps=args.steps, seed=args.seed, gs_options=options,
                       progress=progress, workers=args.workers)
        if args.save_data:
            data.save(args.save_data)
    arch = args.arch or get_domain(data.region.domain).default_predictor
    pred, report = train_predictor(data, arch=arch, dset_kind=args.dset_kind, epochs=args.epochs,
                                   seed=args.seed, progress=progress, lr=args.lr, hidden=args.hidden,
                                   batch_size=args.batch_size, autoregressive=args.autoregressive,
                                   lr_schedule=args.lr_schedule or "linear", influence_lags=args.influence_lags)
    save_predictor(pred, args.out)
    if args.report:
        atomic_write_text(args.report, json.dumps(report, indent=2) + "\n")
    print(format_report(report))
    print(f"wrote {args.out}")
    return 0


def _print_estimate(args, domain, agents, options) -> None:
    """How long the GS collection will take, before it starts (training is extra)."""
    episodes = math.ceil(args.steps / max(domain.steps_of_episode(**options), 1))
    seconds = estimate_evaluation_seconds(args.env, episodes, **options)
    print(f"train-aip: {len(agents)} agents of {args.env}: {args.steps:,} GS steps ({episodes:,} episodes) to "
          f"collect, about {format_seconds(seconds)} on 2 cores; then one stacked training per region shape",
          flush=True)


def _train_set(args, progress: bool) -> int:
    """Every listed agent's AIP from one GS run, into one predictor-set file."""

    if args.data:
        raise CommandError("--data holds one agent's data; several agents are collected in one GS run (leave "
                           "--data out)")
    if not args.env:
        raise CommandError("give --env")
    options = check_collect_arguments(args)
    domain = get_domain(args.env).require_local_simulator("train-aip")
    agents = domain.check_agents(None if args.agent == "all" else args.agent, **options)
    d = dials_of(domain)
    arch = args.arch or d.aip_arch
    _print_estimate(args, domain, agents, options)
    data = collect_all(args.env, agents, steps=args.steps, seed=args.seed, gs_options=options, progress=progress,
                       workers=args.workers)
    mine = arch == d.aip_arch  # the domain's DIALS settings apply to its own architecture
    settings = dict(hidden=args.hidden or (d.aip_hidden if mine else None),
                    lr=args.lr or (d.aip_lr if mine else None), epochs=args.epochs or (d.aip_epochs if mine else None),
                    batch_size=args.batch_size or (d.aip_batch if mine else None), seed=args.seed,
                    dset_kind=args.dset_kind, progress=progress, autoregressive=args.autoregressive,
                    lr_schedule=args.lr_schedule or (d.aip_lr_schedule if mine else "linear"),
                    influence_lags=args.influence_lags)
    preds, report = train_predictors(data, arch, **settings)  # regions of several shapes: one training per shape
    collect_seconds = next(iter(data.values())).metadata["collect_seconds"]
    save_predictor_set(preds.values(), args.out, metadata={
        "steps": next(iter(data.values())).n_steps, "policy": "uniform_random (every listed agent)",
        "options": options, "seed": args.seed, "collect_seconds": collect_seconds,
        "train_seconds": report["train_seconds"], "mean_test_cross_entropy": report["mean_test_cross_entropy"]})
    if args.report:
        atomic_write_text(args.report, json.dumps(report, indent=2) + "\n")
    ce = report["test_cross_entropy"]
    lags = report.get("influence_lags", 1)
    kind = (f"autoregressive {arch}{f' ({lags} lags)' if lags > 1 else ''}" if args.autoregressive else arch)
    print(f"{len(agents)} {kind} AIPs of {args.env}: test cross-entropy mean {report['mean_test_cross_entropy']:.4f} "
          f"(min {min(ce.values()):.4f}, max {max(ce.values()):.4f}); collection {collect_seconds:.1f} s, training "
          f"{report['train_seconds']:.1f} s")
    print(f"wrote {args.out}")
    return 0
