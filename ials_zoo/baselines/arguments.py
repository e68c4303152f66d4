"""The baselines' command lines: a dataclass of arguments becomes ``--options`` (help texts
from the fields), the PPO settings every baseline shares and their checks, ``--env-options``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
import sys
import typing

from ials_zoo.errors import BadInput, is_run_failure
from ials_zoo.policy import MAX_FILE_BYTES, MAX_FRAME_STACK
from ials_zoo.utils import parse_json_object

# --------------------------------------------------------------------------------------------
# dataclass <-> argparse


def add_dataclass_args(parser: argparse.ArgumentParser, cls) -> argparse.ArgumentParser:
    """Add one ``--field-name`` option per field of the dataclass ``cls``.

    The help text of a field is its ``metadata["help"]`` (or what that callable returns, for
    defaults read from the domains when the parser is built); booleans get ``--x/--no-x``. A
    field with ``required=True`` (the domain) is required on the command line and listed first,
    before the settings a base class brings."""
    hints = typing.get_type_hints(cls)
    fields = sorted(dataclasses.fields(cls), key=lambda f: not f.metadata.get("required", False))
    for f in fields:
        name = "--" + f.name.replace("_", "-")
        aliases = list(f.metadata.get("aliases", ()))
        default = f.default if f.default is not dataclasses.MISSING else None
        help_text = f.metadata.get("help", "")
        help_text = help_text() if callable(help_text) else help_text
        required = bool(f.metadata.get("required", False))
        if "default" not in help_text and not required:  # a help that says it already
            help_text = f"{help_text} (default: {default!r})"
        typ = hints[f.name]
        origin = typing.get_origin(typ)
        if origin is typing.Union or str(origin) == "<class 'types.UnionType'>":
            inner = [a for a in typing.get_args(typ) if a is not type(None)]
            typ = inner[0] if inner else str
        if typ is bool:
            parser.add_argument(*aliases, name, dest=f.name, default=default,
                                action=argparse.BooleanOptionalAction, help=help_text)
        else:
            parser.add_argument(*aliases, name, dest=f.name, type=typ, default=default,
                                metavar=f.name.upper(), help=help_text, required=required)
    return parser


def dataclass_from_namespace(cls, ns: argparse.Namespace):
    """Build ``cls`` from the parsed options (fields absent from ``ns`` keep their default)."""
    values = {f.name: getattr(ns, f.name) for f in dataclasses.fields(cls) if hasattr(ns, f.name)}
    return cls(**values)


def parse_args(cls, argv=None, description: str | None = None):
    """Parse a baseline's command line into its dataclass."""
    parser = argparse.ArgumentParser(description=description, allow_abbrev=False)
    add_dataclass_args(parser, cls)
    return dataclass_from_namespace(cls, parser.parse_args(argv))


def run_cli(module) -> int:
    """``python -m`` entry point of a baseline module: parse its ``Args``, run its ``main``;
    bad arguments print one clear line instead of a traceback (``ials-zoo train``'s style)."""

    args = parse_args(module.Args, description=module.__doc__.splitlines()[0])
    name = module.__name__.rsplit(".", 1)[-1]
    try:
        module.main(args)
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return 130
    except (BadInput, FileNotFoundError) as exc:  # any other ValueError is a bug: traceback
        print(f"{name}: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:  # a worker died or stopped, a SUMO error: named by the error itself
        if not is_run_failure(exc):
            raise
        print(f"{name}: {exc}", file=sys.stderr)
        return 1
    return 0


def arg(default, help, **kw):
    """A dataclass field with a help text (a string, or a callable returning one) and optional
    ``aliases``."""
    return dataclasses.field(default=default, metadata={"help": help, **kw})


@dataclasses.dataclass
class PPOSettings:
    """The PPO update settings every baseline shares (SPEC §3: the authors' values)."""

    n_epochs: int = arg(3, "epochs per update")
    learning_rate: float = arg(2.5e-4, "initial learning rate")
    anneal_lr: bool = arg(True, "decay the learning rate linearly to 0")
    clip_range: float = arg(0.1, "PPO clip range")
    ent_coef: float = arg(0.01, "entropy coefficient")
    vf_coef: float = arg(1.0, "value loss coefficient")
    gamma: float = arg(0.99, "discount")
    gae_lambda: float = arg(0.95, "GAE lambda")
    max_grad_norm: float = arg(0.5, "gradient clipping")


@dataclasses.dataclass
class AblatedPPOSettings(PPOSettings):
    """:class:`PPOSettings` with the choices of the PPO ablation (``docs/ablation.md``) that
    every learner of ours shares: lr 1e-3 held constant, 10 epochs per update, gamma 0.95."""

    n_epochs: int = arg(10, "epochs per update")
    learning_rate: float = arg(1e-3, "learning rate")
    anneal_lr: bool = arg(False, "decay the learning rate linearly to 0")
    gamma: float = arg(0.95, "discount")


def check_ppo_settings(args) -> None:
    """Clear errors for the :class:`PPOSettings` fields of ``args``."""

    if args.n_epochs < 1:
        raise BadInput(f"n_epochs must be >= 1, got {args.n_epochs}")
    for name in ("learning_rate", "clip_range", "max_grad_norm"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value > 0):
            raise BadInput(f"{name} must be a finite number > 0, got {value}")
    for name in ("ent_coef", "vf_coef"):
        if not (math.isfinite(getattr(args, name)) and getattr(args, name) >= 0):
            raise BadInput(f"{name} must be a finite number >= 0, got {getattr(args, name)}")
    for name in ("gamma", "gae_lambda"):
        if not 0.0 <= getattr(args, name) <= 1.0:
            raise BadInput(f"{name} must be in [0, 1], got {getattr(args, name)}")


def parse_env_options(text: str | None) -> dict:
    """``--env-options`` (a JSON object of GS/LS options, e.g. ``{"item_lifetime": 8}``)."""

    return parse_json_object(text, "env_options")


MAX_LAYERS, MAX_LAYER_WIDTH = 16, 65_536


def hidden_sizes(net_arch: str, name: str = "net_arch") -> list[int]:
    """Hidden layer sizes from ``"256,128"``; a clear error (naming the argument ``name``) for
    anything else, and for a network whose policy file could not be stored or loaded (the
    hidden layers' float32 weights of an actor and a critic past
    :data:`~ials_zoo.policy.MAX_FILE_BYTES`)."""
    try:
        sizes = [int(x) for x in str(net_arch).split(",") if x.strip()]
    except ValueError:
        sizes = []
    if not sizes or min(sizes) < 1:
        raise BadInput(f"{name} {net_arch!r}: expected comma-separated positive ints, e.g. 256,128")
    weights = 2 * 4 * sum(a * b for a, b in zip(sizes, sizes[1:]))  # actor and critic, float32
    if len(sizes) > MAX_LAYERS or max(sizes) > MAX_LAYER_WIDTH or weights > MAX_FILE_BYTES:
        raise BadInput(f"{name} {str(net_arch)[:100]!r}: at most {MAX_LAYERS} layers of at most {MAX_LAYER_WIDTH:,} "
                       f"units, whose weights fit a policy file ({MAX_FILE_BYTES >> 20} MiB)")
    return sizes


def check_recurrent_hidden(units: int) -> None:
    """``recurrent_hidden``: 0 (no GRU) or a GRU whose three gates' float32 weights fit a policy file."""
    if units < 0 or 3 * 4 * units * units > MAX_FILE_BYTES:
        raise BadInput(f"recurrent_hidden must be >= 0 and a GRU whose weights fit a policy file "
                       f"({MAX_FILE_BYTES >> 20} MiB: at most {int((MAX_FILE_BYTES / 12) ** 0.5):,} units), got {units}")


def check_frame_stack(frame_stack) -> None:
    """``frame_stack``: None (the domain's) or a whole number in [1, MAX_FRAME_STACK]."""
    if frame_stack is not None and not 1 <= frame_stack <= MAX_FRAME_STACK:
        raise BadInput(f"frame_stack must be in [1, {MAX_FRAME_STACK}] (a policy stacks at most "
                       f"{MAX_FRAME_STACK} frames), got {frame_stack}")


def flag_named(message: str, args_class) -> str:
    """A baseline's error as the command line says it: a message that opens with an argument's
    name (``total_timesteps must be >= 1``) opens with its flag (``--total-timesteps``)."""

    first = re.match(r"[a-z_]+", message)
    names = {f.name for f in dataclasses.fields(args_class)}
    if first and first.group(0) in names and message[first.end():first.end() + 1] in (" ", ":", ""):
        return "--" + first.group(0).replace("_", "-") + message[first.end():]
    return message
