"""ials-zoo: benchmark global simulators and influence-augmented local simulators (IALS),
train baselines on either, score them on the GS, and keep a leaderboard.

Each subcommand lives in its own module under ``ials_zoo.commands`` and defines
``configure(parser)`` (add its arguments) and ``run(args) -> int`` (do the work). Modules are
imported only when their subcommand runs, so ``ials-zoo --help`` stays fast.

Errors: bad input is reported as ``ials-zoo <command>: <what is wrong>``, exit status 2, no
traceback (``IALS_ZOO_DEBUG=1`` shows it); Ctrl-C ends a command with exit status 130.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import signal
import sys
import threading

from ials_zoo._version import __version__
from ials_zoo.core.domains import domain_ids
from ials_zoo.core.extras import tools_of
from ials_zoo.errors import BadInput, is_run_failure

SUBCOMMANDS = {
    # name: (module, one-line help)
    "bench": ("ials_zoo.commands.bench", "measure GS and IALS speed (steps/s, cost per agent-step)"),
    "demo": ("ials_zoo.commands.demo", "run one episode of a GS and print what happened"),
    "collect": ("ials_zoo.commands.collect", "collect (d_t, u_t) data from a GS (Algorithm 1)"),
    "train-aip": ("ials_zoo.commands.train_aip", "train an approximate influence predictor"),
    "train": ("ials_zoo.commands.train", "train a baseline: PPO for one agent; IPPO, IDQN or DIALS for all"),
    "evaluate": ("ials_zoo.commands.evaluate", "score a policy on the GS"),
    "leaderboard": ("ials_zoo.commands.leaderboard", "submit, show, render, verify results"),
    "reproduce": ("ials_zoo.commands.reproduce", "reproduce the paper's experiments"),
    "rates": ("ials_zoo.commands.rates", "how much influence an IALS injects, per predictor"),
    "fidelity": ("ials_zoo.commands.fidelity", "does the multi-agent IALS reproduce the GS's influence over time?"),
}


def _available() -> dict:
    """The subcommands: the generic ones, then each domain's own tools (``tools_of(domain)``)."""
    found = {}
    for name, (module, help_text) in SUBCOMMANDS.items():
        if importlib.util.find_spec(module) is not None:
            found[name] = (module, help_text)
    for env_id in domain_ids():
        for name, (module, help_text) in tools_of(env_id).items():
            found.setdefault(name, (module, f"{help_text} ({env_id})"))
    return found


class _Parser(argparse.ArgumentParser):
    """argparse with the zoo's error line: ``ials-zoo <command>: <message>``, exit 2, and no
    abbreviated options (``--total-time`` is a typo, not ``--total-timesteps``)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message):
        self.print_usage(sys.stderr)
        self.exit(2, f"{self.prog}: {message}\n")


def build_parser(load: str | None = None) -> argparse.ArgumentParser:
    parser = _Parser(prog="ials-zoo", description=__doc__.split("\n\n")[0].replace("\n", " "))
    parser.add_argument("--version", action="version", version=f"ials-zoo {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    parser.commands = {}
    for name, (module, help_text) in _available().items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        parser.commands[name] = p
        if name == load:
            importlib.import_module(module).configure(p)
    return parser


def _deepest(parser, argv: list[str]):
    """The (sub)parser that reads the end of ``argv``: an unknown option is that parser's error
    (its usage), not the top level's."""
    for token in argv:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction) and token in action.choices:
                return _deepest(action.choices[token], argv[argv.index(token) + 1:])
    return parser


def threading_main() -> bool:
    return threading.current_thread() is threading.main_thread()


def _sigterm_interrupts() -> None:
    """SIGTERM ends a command like Ctrl-C: cleanup runs (workers stopped, the run folder marked
    interrupted) before the process exits."""

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    if threading_main():
        signal.signal(signal.SIGTERM, interrupt)


def _noted_interrupts():
    """The start-up's Ctrl-C handler, which only notes an interrupt (the package's, installed as
    it started importing: ``ials_zoo._quiet_interrupts_while_starting``; else one put in now
    where Python's own is in place): a KeyboardInterrupt raised inside compiled code (torch's
    imports) aborts the process. A noted Ctrl-C leaves the signal's default action in place, so
    a second one ends the process at once. None where it is not ours to handle (another thread,
    another program's handler)."""

    if not threading_main():
        return None
    handler = signal.getsignal(signal.SIGINT)
    if getattr(handler, "ials_zoo_startup", False):
        return handler
    if handler is not signal.default_int_handler:
        return None

    def noted(signum, frame):
        noted.pending = True
        signal.signal(signal.SIGINT, signal.SIG_DFL)  # a second Ctrl-C: the user means it now

    noted.pending, noted.ials_zoo_startup = False, True
    signal.signal(signal.SIGINT, noted)
    return noted


def _python_interrupts(noted) -> None:
    """Give Ctrl-C back to Python (a KeyboardInterrupt, handled by :func:`_run`) once the
    start-up, with its imports, is done: in place of the noting handler, or of the default
    action it left after a Ctrl-C."""

    if not threading_main() or noted is None:
        return
    handler = signal.getsignal(signal.SIGINT)
    if handler is noted or (handler is signal.SIG_DFL and noted.pending):
        signal.signal(signal.SIGINT, signal.default_int_handler)


def _start(argv: list[str]):
    """``(parser, args, extra, module)``: the parser, with the command's own options, and the
    command's module, imported (module None without a command)."""
    command = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(load=command)
    args, extra = parser.parse_known_args(argv)
    module = importlib.import_module(_available()[args.command][0]) if args.command and not extra else None
    return parser, args, extra, module


def _interrupted(command: str | None = None) -> int:
    print(f"ials-zoo{' ' + command if command else ''}: interrupted", file=sys.stderr)
    return 130


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    noted = _noted_interrupts()
    try:
        try:
            parser, args, extra, module = _start(argv)
        except KeyboardInterrupt:  # raised by Python code where no handler of ours was in place
            return _interrupted()
        except SystemExit:  # --help, or a parser error: a Ctrl-C meanwhile still says so
            if noted is not None and noted.pending:
                return _interrupted()
            raise
        if noted is not None and noted.pending:  # Ctrl-C while starting up: the imports finished, no traceback
            return _interrupted()
        if extra:
            _deepest(parser, argv).error(f"unrecognized arguments: {' '.join(extra)}")
        if args.command is None:
            parser.print_help()
            return 2
        return _run(module, args, noted)
    finally:
        _python_interrupts(noted)


def _run(module, args, noted) -> int:
    """The command's ``run``, its errors as the module docstring says."""
    _sigterm_interrupts()
    try:
        _python_interrupts(noted)  # from here a Ctrl-C is a KeyboardInterrupt, handled below
        if noted is not None and noted.pending:  # one that came since the start-up's check
            return _interrupted(args.command)
        return int(module.run(args) or 0)
    except KeyboardInterrupt:
        return _interrupted(args.command)
    except (BadInput, FileNotFoundError, PermissionError, IsADirectoryError) as exc:
        # bad input names itself (ials_zoo.errors); any other ValueError/TypeError is a bug: traceback
        if os.environ.get("IALS_ZOO_DEBUG"):
            raise
        print(f"ials-zoo {args.command}: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:
        # a worker that died or stopped, a SUMO error: named by the error itself, exit 1
        if not is_run_failure(exc) or os.environ.get("IALS_ZOO_DEBUG"):
            raise
        print(f"ials-zoo {args.command}: {exc}", file=sys.stderr)
        return 1
    finally:
        if threading_main():
            signal.signal(signal.SIGTERM, signal.SIG_DFL)


if __name__ == "__main__":
    sys.exit(main())
