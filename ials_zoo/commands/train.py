"""``ials-zoo train BASELINE [options]``: train a PPO baseline (see ``ials_zoo.baselines``).

    ials-zoo train ppo_single --env warehouse_v0 --simulator ials --total-timesteps 200000
    ials-zoo train ppo_shared --env warehouse_v0 --total-timesteps 200000
    ials-zoo train ppo_single --help
"""

from __future__ import annotations

import importlib
import sys


def configure(parser):
    from ials_zoo.baselines import BASELINES
    from ials_zoo.baselines.common import add_dataclass_args

    sub = parser.add_subparsers(dest="baseline", metavar="BASELINE", required=True)
    for name, module_name in BASELINES.items():
        module = importlib.import_module(module_name)
        p = sub.add_parser(name, help=module.__doc__.splitlines()[0],
                           description=module.__doc__.splitlines()[0])
        add_dataclass_args(p, module.Args)


def run(args) -> int:
    from ials_zoo.baselines import BASELINES
    from ials_zoo.baselines.common import dataclass_from_namespace

    module = importlib.import_module(BASELINES[args.baseline])
    try:
        module.main(dataclass_from_namespace(module.Args, args))
    except (ValueError, TypeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0
