"""``ials-zoo evaluate``: score a policy on the GS (other agents scripted) and write a
leaderboard result JSON.

    ials-zoo evaluate --env warehouse_v0 --agent robot_20 --policy scripted --episodes 30 --out r.json
    ials-zoo evaluate --policy runs/warehouse_v0__robot_20__ials__s0/model.zip --out r.json

``--policy``: ``random``, ``scripted``, a saved baseline model (``.zip`` with its
``.meta.json`` sidecar: domain, agent and frame stack come from it) or ``module:function``.
Protocol (seeds 10000 + i, 95% Student-t CI): :mod:`ials_zoo.evaluation`.
"""

from __future__ import annotations

import json
import sys


def configure(parser):
    parser.add_argument("--env", dest="env_id", default=None,
                        help="domain id (default: from the model's metadata)")
    parser.add_argument("--agent", default=None,
                        help="agent to control (default: the model's, else the domain's default)")
    parser.add_argument("--policy", required=True,
                        help="random | scripted | PATH.zip (baseline model) | module:function")
    parser.add_argument("--episodes", type=int, default=20, help="episodes (seeds 10000..)")
    parser.add_argument("--deterministic", action="store_true",
                        help="take the most likely action (models) instead of sampling")
    parser.add_argument("--frame-stack", type=int, default=None,
                        help="override the policy's frame stack (callables default to 1)")
    parser.add_argument("--env-options", default="",
                        help="GS options as a JSON object, e.g. '{\"item_lifetime\": 8}' "
                             "(default: the model's training options)")
    parser.add_argument("--out", default=None, help="write the result JSON here (atomic)")
    parser.add_argument("--submitter", default="", help="submitter name in the result")
    parser.add_argument("--notes", default="", help="notes in the result")
    parser.add_argument("--no-progress", dest="progress", action="store_false",
                        help="no progress bar")


def result_for(env_id, agent, policy, episodes, deterministic=False, frame_stack=None,
               submitter="", notes="", progress=False, options: dict | None = None) -> dict:
    """Evaluate ``policy`` and build its leaderboard result (training record from a model's
    metadata; none for reference policies and callables)."""
    from ials_zoo.core.domains import get_domain
    from ials_zoo.evaluation import evaluate, load_policy
    from ials_zoo.leaderboard import make_result

    probe = load_policy(policy) if str(policy).endswith(".zip") else None
    meta = probe.metadata if probe is not None else {}
    env_id = env_id or meta.get("env_id")
    if env_id is None:
        raise ValueError("--env is required unless the policy is a model with metadata")
    agent = agent or meta.get("agent") or get_domain(env_id).default_agents[0]
    options = meta.get("env_options", {}) if options is None else options
    ev = evaluate(env_id, agent, probe or policy, episodes=episodes, deterministic=deterministic,
                  frame_stack=frame_stack, progress=progress, **options)
    if meta:
        training = meta.get("training")
        curve = meta.get("learning_curve") or []
        seed = meta.get("seed")
        return make_result([ev], algorithm=meta.get("algorithm", "model"), training=training,
                           training_seeds=[seed],
                           learning_curves=[{"seed": seed, "points": curve}] if curve else [],
                           trained_agents=meta.get("agents", [agent]),
                           submitter=submitter, notes=notes)
    algorithm = ev.policy_kind if ev.policy_kind in ("random", "scripted") else "callable"
    return make_result([ev], algorithm=algorithm, submitter=submitter, notes=notes)


def run(args) -> int:
    from ials_zoo.baselines.common import parse_env_options
    from ials_zoo.leaderboard import write_result

    try:
        options = parse_env_options(args.env_options) if args.env_options else None
        result = result_for(args.env_id, args.agent, args.policy, args.episodes,
                            args.deterministic, args.frame_stack, args.submitter, args.notes,
                            args.progress, options)
    except (ValueError, TypeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    s = result["score"]
    print(f"{result['env_id']} {result['agent']} policy={result['policy']['name']}: "
          f"GS mean return {s['mean']:.3f}, 95% CI [{s['ci_low']:.3f}, {s['ci_high']:.3f}] "
          f"over {result['evaluation']['episodes']} episodes")
    if args.out:
        write_result(args.out, result)
        print(f"wrote {args.out}")
    else:
        print(json.dumps(result["score"]))
    return 0
