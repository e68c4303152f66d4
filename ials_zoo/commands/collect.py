"""``ials-zoo collect``: record ``(d_t, u_t)`` data from a GS (Algorithm 1).

Examples::

    ials-zoo collect --env warehouse_v0 --agent robot_20 --steps 50000 --out wh.npz
    ials-zoo collect --env traffic_grid_v0 --agent all --steps 10000 --out-dir data/

With one ``--agent`` the learner follows a uniformly random policy and every other agent is
scripted; the output is an :class:`ials_zoo.influence.InfluenceDataset` ``.npz`` file (format
documented in ``ials_zoo.influence.dataset``). With several agents (or ``all``) one GS run
records every listed region at once (all of them acting randomly) into
``--out-dir/<agent>.npz``.
"""

from __future__ import annotations

from pathlib import Path

from ials_zoo.commands import NET_HELP, CommandError, with_network
from ials_zoo.core.domains import domain_ids, get_domain
from ials_zoo.influence.dataset import collect_all
from ials_zoo.utils import check_output_file, check_seed, parse_json_object, remove_stale_temporaries


def _json_dict(text: str) -> dict:
    return parse_json_object(text, "--options")


def add_collect_arguments(parser, required: bool = True) -> None:
    """Arguments shared by ``collect`` and ``train-aip``."""

    parser.add_argument("--env", required=required, help="domain id",
                        choices=[d for d in domain_ids() if get_domain(d).has_local_simulator])
    parser.add_argument("--agent", required=required,
                        help="learning agent, e.g. robot_20; 'all' (or a comma-separated list): every agent's data "
                             "from one GS run")
    parser.add_argument("--steps", type=int, default=50_000,
                        help="steps to record, rounded up to whole episodes (default 50000)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--options", default="{}",
                        help='GS options as JSON, e.g. \'{"item_lifetime": 8}\'')
    parser.add_argument("--net", default=None, metavar="NAME", help=NET_HELP)
    parser.add_argument("--workers", type=int, default=1,
                        help="GS processes collecting at once (each records steps/workers; worth it for SUMO)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def check_collect_arguments(args) -> dict:
    """Clear errors for the shared arguments before anything runs; returns the GS options."""

    if args.steps < 1:
        raise CommandError(f"--steps must be >= 1, got {args.steps}")
    if args.workers < 1:
        raise CommandError(f"--workers must be >= 1, got {args.workers}")
    check_seed(args.seed, "--seed")
    options = _json_dict(args.options)
    if args.net is not None and args.env is None:
        raise CommandError("--net needs --env")
    if args.env is not None:
        domain = get_domain(args.env)
        options = with_network(domain, options, args.net)
        if args.agent is not None and args.agent != "all":
            for a in args.agent.split(","):
                domain.check_agent(a.strip(), **options)
        probe = domain.agents(**options)[0]
        domain.region_spec(probe, **options)  # option values
        env = domain.parallel_env(learners=[probe], **options)  # unknown options
        env.close()
    return options


def configure(parser):
    add_collect_arguments(parser)
    parser.add_argument("--out", default=None, help="output .npz file (one agent)")
    parser.add_argument("--out-dir", default=None, help="output folder, one <agent>.npz per agent")


def run(args) -> int:

    options = check_collect_arguments(args)
    agents = None if args.agent == "all" else [a.strip() for a in args.agent.split(",") if a.strip()]
    several = agents is None or len(agents) > 1
    if several and not args.out_dir:
        raise CommandError("several agents: give --out-dir (one <agent>.npz each)")
    if not several and not (args.out or args.out_dir):
        raise CommandError("give --out FILE.npz (or --out-dir)")
    if args.out:
        if several:
            raise CommandError("--out takes one agent's data; use --out-dir for several agents")
        targets = {agents[0]: check_output_file(args.out, "--out")}
    else:

        names = get_domain(args.env).check_agents(agents, **options)
        targets = {a: check_output_file(Path(args.out_dir) / f"{a}.npz", "--out-dir") for a in names}
    for path in targets.values():
        remove_stale_temporaries(path.parent)
    data = collect_all(args.env, list(targets), steps=args.steps, seed=args.seed, gs_options=options,
                       progress=not args.no_progress, workers=args.workers)
    for a, path in targets.items():
        data[a].save(path)
    first = next(iter(data.values()))
    m = first.metadata
    what = next(iter(targets.values())) if len(targets) == 1 else f"{len(targets)} files in {args.out_dir}"
    print(
        f"wrote {what}: {first.n_episodes} episodes x {first.episode_length} steps of "
        f"{args.env} ({len(targets)} region{'s' if len(targets) > 1 else ''}; {m['collect_seconds']:.1f} s, "
        f"{first.n_steps / max(m['collect_seconds'], 1e-9):,.0f} GS steps/s)"
    )
    return 0
