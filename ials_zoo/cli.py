"""ials-zoo: global simulators, influence-augmented local simulators, baselines, leaderboard.

Each subcommand lives in its own module under ``ials_zoo.commands`` and defines
``configure(parser)`` (add its arguments) and ``run(args) -> int`` (do the work). Modules are
imported only when their subcommand runs, so ``ials-zoo --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys

SUBCOMMANDS = {
    # name: (module, one-line help)
    "bench": ("ials_zoo.commands.bench", "measure GS and IALS steps/s"),
    "demo": ("ials_zoo.commands.demo", "run a short episode and print what happened"),
    "collect": ("ials_zoo.commands.collect", "collect (d_t, u_t) data from a GS (Algorithm 1)"),
    "train-aip": ("ials_zoo.commands.train_aip", "train an approximate influence predictor"),
    "train": ("ials_zoo.commands.train", "train a PPO baseline on a GS or an IALS"),
    "evaluate": ("ials_zoo.commands.evaluate", "score a policy on the GS"),
    "leaderboard": ("ials_zoo.commands.leaderboard", "submit, show, render, verify results"),
    "reproduce": ("ials_zoo.commands.reproduce", "reproduce the paper's experiments"),
}


def _available() -> dict:
    found = {}
    for name, (module, help_text) in SUBCOMMANDS.items():
        if importlib.util.find_spec(module) is not None:
            found[name] = (module, help_text)
    return found


def build_parser(load: str | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ials-zoo", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_text) in _available().items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        if name == load:
            importlib.import_module(module).configure(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    command = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(load=command if command in SUBCOMMANDS else None)
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    module = importlib.import_module(_available()[args.command][0])
    try:
        return int(module.run(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
