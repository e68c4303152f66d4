"""``ials-zoo evaluate``: score a policy on the GS and write a leaderboard result JSON.

    ials-zoo evaluate --env warehouse_v0 --agent robot_20 --policy scripted --out r.json
    ials-zoo evaluate --policy runs/warehouse_v0__robot_20__gs__s0/policy.safetensors --out r.json
    ials-zoo evaluate --env traffic_grid_v0 --joint --policy runs/dials_traffic/policy.safetensors
    ials-zoo evaluate --env sumo_net_v0 --env-options '{"net": "cologne8"}' --joint --policy rule:greedy

``--policy``: ``random``, ``scripted``, ``rule:NAME`` (a rule of the domain, every agent at once), a policy file (``.safetensors``: weights + JSON), an
SB3 PPO ``.zip`` with its ``.meta.json`` sidecar (read without unpickling), or
``module:function`` -- a callable ``fn(obs) -> action`` importable from the current folder
(it reads ``fn.frame_stack`` stacked observations, default 1; a result of such code can be
kept locally but never submitted). ``--joint`` scores every agent at once (the multi-agent
track); a policy file with several agents is scored jointly by default.
Protocol (20 episodes, seeds 10000 + i, 95% bootstrap interval): :mod:`ials_zoo.evaluation`.
"""

from __future__ import annotations

from ials_zoo.baselines.arguments import parse_env_options
from ials_zoo.commands import CommandError
from ials_zoo.core.domains import domain_ids, get_domain
from ials_zoo.evaluation import PROTOCOL_EPISODES
from ials_zoo.leaderboard import write_result
from ials_zoo.leaderboard.build import external_training, result_for
from ials_zoo.utils import check_output_file, check_seed


def configure(parser):

    parser.add_argument("--env", dest="env_id", default=None,
                        help=f"domain id, one of {', '.join(domain_ids())} (default: from the policy file)")
    parser.add_argument("--agent", default=None,
                        help="agent to control (default: the policy's, else the domain's first paper agent)")
    parser.add_argument("--joint", action="store_true",
                        help="every agent acts with its own policy (multi-agent track)")
    parser.add_argument("--policy", required=True,
                        help="random | scripted | rule:NAME (a rule of the domain driving every agent, --joint; "
                             "sumo_net_v0: rule:fixed, rule:actuated, rule:greedy, rule:max_pressure) | "
                             "FILE.safetensors | FILE.zip (SB3) | module:function (a callable "
                             "fn(obs) -> action importable from the current folder; fn.frame_stack "
                             "observations, default 1; local results only, never submitted)")
    parser.add_argument("--episodes", type=int, default=PROTOCOL_EPISODES,
                        help=f"episodes, seeds 10000.. (default: the protocol's {PROTOCOL_EPISODES})")
    parser.add_argument("--deterministic", action="store_true",
                        help="take the most likely action (models) instead of sampling")
    parser.add_argument("--frame-stack", type=int, default=None,
                        help="observations a callable policy reads (a model's own is used)")
    parser.add_argument("--env-options", default="",
                        help="GS options as a JSON object, e.g. '{\"item_lifetime\": 8}' "
                             "(default: the model's training options; any option makes a protocol variant)")
    parser.add_argument("--out", default=None, help="write the result JSON here (atomic)")
    parser.add_argument("--algorithm", default=None,
                        help="for a policy trained elsewhere (no training record in its file): the algorithm that "
                             "trained it; with --env-steps, --out writes an entry labelled external")
    parser.add_argument("--env-steps", type=int, default=None,
                        help="for a policy trained elsewhere: the environment steps its training took (claimed)")
    parser.add_argument("--training-seconds", type=float, default=0.0,
                        help="for a policy trained elsewhere: its training wall-clock (claimed)")
    parser.add_argument("--training-seed", type=int, default=0, help="for a policy trained elsewhere: its seed")
    parser.add_argument("--submitter", default="", help="submitter name in the result")
    parser.add_argument("--notes", default="", help="notes in the result")
    parser.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")


def run(args) -> int:

    if args.episodes < 1:
        raise CommandError(f"--episodes must be >= 1, got {args.episodes}")
    if args.frame_stack is not None and args.frame_stack < 1:
        raise CommandError(f"--frame-stack must be >= 1, got {args.frame_stack}")
    if args.out:
        check_output_file(args.out, "--out")
    options = parse_env_options(args.env_options) if args.env_options else None
    external = None
    if args.algorithm is not None or args.env_steps is not None:
        if args.algorithm is None or args.env_steps is None:
            raise CommandError("--algorithm and --env-steps go together (the training claims of a policy trained "
                               "elsewhere)")
        check_seed(args.training_seed, "--training-seed")
        external = external_training(args.algorithm, args.env_steps, args.training_seconds, args.training_seed)
    result = result_for(args.env_id, args.agent, args.policy, args.episodes, args.deterministic,
                        args.frame_stack, args.submitter, args.notes, args.progress, options, args.joint,
                        external=external, need_record=bool(args.out))
    s = result["score"]
    who = result["agent"] or f"{len(result['agents'])} agents (mean over agents)"
    print(f"{result['env_id']} {who}, policy {result['policy']['name']} ({result['policy']['kind']}): GS mean "
          f"return {s['mean']:.3f}, 95% CI [{s['ci_low']:.3f}, {s['ci_high']:.3f}] over "
          f"{result['evaluation']['episodes']} episodes ({result['evaluation']['protocol']} protocol)")
    rank = get_domain(result["env_id"]).score_metric
    if rank is not None and rank in (result.get("metrics") or {}):
        m = result["metrics"][rank]
        print(f"  {rank} (ranks the board, {get_domain(result['env_id']).metrics[rank]} is better): {m['mean']:.3f}, "
              f"95% CI [{m['ci_low']:.3f}, {m['ci_high']:.3f}]")
    if args.out:  # a network of the user's own makes a result that stays local (submit refuses it)
        write_result(args.out, result, local=bool(set(result["evaluation"]["options"])
                                                  & set(get_domain(result["env_id"]).file_options)))
        print(f"wrote {args.out}")
    return 0
