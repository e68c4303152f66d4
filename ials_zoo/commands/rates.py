"""``ials-zoo rates``: how much influence an IALS injects under each predictor.

    ials-zoo rates --env traffic_grid_v0 --agent tls_12 --predictors untrained,fixed:0.1,trained

Prints, per predictor, the mean influence value per source and step (in traffic: vehicles
entering per lane and step) and the mean observation, over ``--episodes`` IALS episodes of a
uniform random policy (:func:`ials_zoo.influence.rates.influence_rates`).
"""

from __future__ import annotations

from ials_zoo.commands import CommandError
from ials_zoo.core.domains import get_domain, ials_domain_ids
from ials_zoo.influence.rates import influence_rates
from ials_zoo.influence.specs import parse_predictor


def configure(parser):
    parser.add_argument("--env", required=True, choices=ials_domain_ids(), help="domain id")
    parser.add_argument("--agent", default=None, help="agent (default: the domain's first paper agent)")
    parser.add_argument("--predictors", default="untrained,fixed:0.1,trained",
                        help="comma-separated predictor specs")
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)


def run(args) -> int:

    domain = get_domain(args.env)
    agent = domain.check_agent(args.agent or domain.default_agents[0])
    if args.episodes < 1:
        raise CommandError(f"--episodes must be >= 1, got {args.episodes}")
    preds = [p.strip() for p in args.predictors.split(",") if p.strip()]
    if not preds:
        raise CommandError("--predictors names no predictor")
    for p in preds:
        parse_predictor(p)
    for pred in preds:
        r = influence_rates(args.env, agent, pred, args.episodes, seed=args.seed)
        print(f"{pred:<24} influence per source and step {r['influence_mean']:.3f}   "
              f"observation mean {r['observation_mean']:.3f}   ({r['steps']} steps)")
    return 0
