"""``ials-zoo train BASELINE [options]``: train a baseline (see ``ials_zoo.baselines``).

    ials-zoo train ppo_single --env warehouse_v0 --simulator ials --total-timesteps 200000
    ials-zoo train ppo_shared --env warehouse_v0 --total-timesteps 200000
    ials-zoo train ippo --env traffic_grid_v0 --simulator gs
    ials-zoo train dials --env traffic_grid_v0 [--workers 2] [--backend ray]
    ials-zoo train dials --help
"""

from __future__ import annotations

import importlib

from ials_zoo.baselines import BASELINES
from ials_zoo.baselines.arguments import add_dataclass_args, dataclass_from_namespace, flag_named
from ials_zoo.errors import BadInput


def configure(parser):

    sub = parser.add_subparsers(dest="baseline", metavar="BASELINE", required=True)
    for name, module_name in BASELINES.items():
        module = importlib.import_module(module_name)
        p = sub.add_parser(name, help=module.__doc__.splitlines()[0],
                           description=module.__doc__.splitlines()[0])
        add_dataclass_args(p, module.Args)


def run(args) -> int:
    module = importlib.import_module(BASELINES[args.baseline])
    try:
        module.main(dataclass_from_namespace(module.Args, args))
    except BadInput as exc:
        named = flag_named(str(exc), module.Args)
        if named == str(exc):
            raise
        raise BadInput(named) from None  # one line, the flag named (any BadInput: a ResultError takes a field too)
    return 0

