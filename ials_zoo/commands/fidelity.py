"""``ials-zoo fidelity``: does the multi-agent IALS reproduce the GS's influence over whole
trajectories, under several joint policies? (:mod:`ials_zoo.influence.fidelity`)

    ials-zoo fidelity --env warehouse_v0
    ials-zoo fidelity --env traffic_grid_v0 --episodes 20 --policies random,constant,scripted
    ials-zoo fidelity --env warehouse_v0 --policies random,leaderboard/policies/<sha>.safetensors --out f.md
    ials-zoo fidelity --env warehouse_v0 --predictor on-policy-autoregressive [--aip-seeds 3]
    ials-zoo fidelity --env sumo_net_v0 --net cologne8 --policies random,constant --predictor on-policy
    ials-zoo fidelity --env sumo_net_v0 --net cologne8 --local arrays --predictor on-policy
"""

from __future__ import annotations

import math
import os

from ials_zoo.commands import NET_HELP, with_network
from ials_zoo.core.domains import LOCAL_SIMULATORS, domain_ids, get_domain
from ials_zoo.errors import BadInput
from ials_zoo.evaluation import estimate_evaluation_seconds
from ials_zoo.influence.base import MAX_INFLUENCE_LAGS
from ials_zoo.influence.fidelity import ON_POLICY, fidelity_report, markdown, parse_cycle
from ials_zoo.influence.train import LR_SCHEDULES
from ials_zoo.utils import atomic_write_text, check_output_file, check_seed, format_seconds, parse_json_object

MAX_EPISODES = 100_000  # per policy and simulator: 10**12 is a typo, not a study


def configure(parser):
    parser.add_argument("--env", required=True,
                        help="domain id, one of " + ", ".join(d for d in domain_ids() if get_domain(d).has_ials_parallel_env))
    parser.add_argument("--options", default=None,
                        help="the domain's options as a JSON object, e.g. '{\"net\": \"cologne8\"}' for sumo_net_v0")
    parser.add_argument("--net", default=None, metavar="NAME", help=NET_HELP)
    parser.add_argument("--policies", default="random,constant,scripted",
                        help="joint policies, comma-separated: random, constant, cycle:H (each agent cycles through "
                             "its actions, H steps each: a fixed-time plan), scripted (GS only) or policy files")
    parser.add_argument("--episodes", type=int, default=20, help="episodes per policy and simulator")
    parser.add_argument("--agents", default=None, help="agents to report, comma-separated (default: a corner, an "
                        "edge and the domain's default agent)")
    parser.add_argument("--predictor", default="trained",
                        help="the IALS's AIPs: a predictor spec or an AIP set file (one set for every policy), or "
                             "on-policy / on-policy-autoregressive (AIPs trained on GS data of each policy)")
    parser.add_argument("--collect-steps", type=int, default=None,
                        help="GS steps of each policy's AIP data with --predictor on-policy* (default: the domain's "
                             "fidelity_collect_steps, e.g. 100,000 for traffic, else its DIALS collection)")
    parser.add_argument("--aip-lr", type=float, default=None,
                        help="learning rate of the on-policy AIPs (default: the domain's fidelity_aip_lr, "
                             "e.g. 3e-3: trained until their trajectories match the GS's, longer than DIALS does)")
    parser.add_argument("--aip-epochs", type=int, default=None,
                        help="epochs of the on-policy AIPs (default: the domain's fidelity_aip_epochs, e.g. 120 for "
                             "the warehouse's GRUs, 30 for traffic's MLPs)")
    parser.add_argument("--aip-lr-schedule", default=None,
                        help="linear or constant: the learning rate of the on-policy AIPs over their training "
                             "(default: the domain's fidelity_aip_lr_schedule, linear decay to 0)")
    parser.add_argument("--aip-influence-lags", type=int, default=None,
                        help="with --predictor on-policy-autoregressive: how many past steps of their own draws "
                             "the AIPs read (default: the domain's fidelity_aip_influence_lags, e.g. 3 for traffic)")
    parser.add_argument("--aip-clock-horizon", type=int, default=None,
                        help="with --predictor on-policy*: H > 0 makes the AIPs also read the time since the episode's "
                             "start, min(t, H) / H (0: no clock; default: the domain's fidelity_aip_clock_horizon)")
    parser.add_argument("--aip-seeds", type=int, default=1,
                        help="with --predictor on-policy*: train the AIPs this many times (other GS data and "
                             "training seeds) and count per row under how many trainings it holds")
    parser.add_argument("--local", default="sumo",
                        help="the IALS's local simulators, where the domain has a choice: sumo (every region cut "
                             "from the network) | arrays (numpy arrays: ials_zoo.sumo_net.arrays)")
    parser.add_argument("--tolerance", type=float, default=0.1, help="relative difference that holds anyway")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="also write the Markdown report here (atomic)")


def _check_local(domain, local: str) -> None:
    if local not in LOCAL_SIMULATORS:
        raise BadInput(f"--local: expected one of {', '.join(LOCAL_SIMULATORS)}, got {local!r}")
    if local != "sumo" and domain.ials_batched_env is None:
        raise BadInput(f"--local {local}: {domain.env_id}'s IALS has one local simulator, no choice")


def run(args) -> int:

    domain = get_domain(args.env).require_ials_parallel_env("fidelity")
    options = with_network(domain, parse_json_object(args.options, "--options") if args.options else {}, args.net)
    if args.episodes < 2:
        raise BadInput(f"--episodes must be >= 2 (intervals over episodes), got {args.episodes}")
    if not args.tolerance >= 0:
        raise BadInput(f"--tolerance must be >= 0, got {args.tolerance}")
    check_seed(args.seed, "--seed")
    policies = [p.strip() for p in args.policies.split(",") if p.strip()]
    if not policies:
        raise BadInput(f"--policies names no policy ({args.policies!r}); give e.g. random,constant,scripted")
    if args.episodes > MAX_EPISODES:
        raise BadInput(f"--episodes must be <= {MAX_EPISODES:,}, got {args.episodes:,}")
    for p in policies:
        try:
            cycle = parse_cycle(p)
        except BadInput as exc:
            raise BadInput(f"--policies: {exc}") from None
        if p not in ("random", "constant", "scripted") and cycle is None and not os.path.isfile(p):
            raise BadInput(f"--policies: {p!r} is neither random, constant, cycle:H, scripted nor a policy file")
    _check_local(domain, args.local)
    watched = None if args.agents is None else domain.check_agents(args.agents, **options)
    for name in ("collect_steps", "aip_epochs", "aip_seeds", "aip_influence_lags"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            raise BadInput(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    if args.aip_influence_lags is not None and args.aip_influence_lags > MAX_INFLUENCE_LAGS:
        raise BadInput(f"--aip-influence-lags must be <= {MAX_INFLUENCE_LAGS} (past draws an AIP reads; the "
                       f"domains use 1-3), got {args.aip_influence_lags:,}")
    if args.aip_lr is not None and not (math.isfinite(args.aip_lr) and args.aip_lr > 0):
        raise BadInput(f"--aip-lr must be a finite number > 0, got {args.aip_lr}")
    if args.aip_lr_schedule is not None and args.aip_lr_schedule not in LR_SCHEDULES:
        raise BadInput(f"--aip-lr-schedule must be one of {', '.join(LR_SCHEDULES)}, got {args.aip_lr_schedule!r}")
    if args.aip_seeds > 1 and args.predictor not in ON_POLICY:
        raise BadInput(f"--aip-seeds {args.aip_seeds} needs --predictor on-policy or on-policy-autoregressive "
                       f"(AIPs trained per run), got {args.predictor!r}")
    if args.aip_influence_lags is not None and args.predictor != "on-policy-autoregressive":
        raise BadInput(f"--aip-influence-lags needs --predictor on-policy-autoregressive, got {args.predictor!r}")
    if args.aip_clock_horizon is not None and (args.aip_clock_horizon < 0 or args.predictor not in ON_POLICY):
        raise BadInput(f"--aip-clock-horizon must be >= 0 and needs --predictor on-policy or "
                       f"on-policy-autoregressive, got {args.aip_clock_horizon} with {args.predictor!r}")
    if args.out:
        check_output_file(args.out)
    gs_seconds = estimate_evaluation_seconds(args.env, args.episodes, **options)
    print(f"fidelity {args.env}: {len(policies)} joint polic{'ies' if len(policies) > 1 else 'y'} x {args.episodes:,} "
          f"episodes on the GS and on the IALS: about {format_seconds(2 * len(policies) * gs_seconds)} on 2 cores "
          "(the GS's episodes, and the IALS's charged as the GS's: an upper estimate; AIP data and training extra)",
          flush=True)
    report = fidelity_report(args.env, policies, episodes=args.episodes, seed=args.seed, watched=watched,
                             predictor=args.predictor, tolerance=args.tolerance, collect_steps=args.collect_steps,
                             aip_lr=args.aip_lr, aip_epochs=args.aip_epochs, aip_seeds=args.aip_seeds,
                             aip_lr_schedule=args.aip_lr_schedule, aip_influence_lags=args.aip_influence_lags,
                             aip_clock_horizon=args.aip_clock_horizon,
                             ials_options={"local": args.local} if args.local != "sumo" else None, **options)
    text = markdown(report)
    print(text)
    if args.out:
        atomic_write_text(args.out, text + "\n")
    return 0
