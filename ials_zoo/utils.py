"""Small shared helpers: atomic file writes, JSON option parsing, seed checks."""

from __future__ import annotations

import contextlib
import json
import os
import re
import stat
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from ials_zoo.errors import BadInput, BadInputType

_UMASK = os.umask(0)
os.umask(_UMASK)


TEMP_PREFIX = ".~"
"""Temporary files of :func:`atomic_path` are called ``.~<name>.<random><suffix>``: hidden
(no ``*.json`` glob lists them) and recognisable (:func:`remove_stale_temporaries`)."""


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = ""):
    """Yield a temporary path next to ``path``; on success rename it onto ``path``.

    Nothing half-written is ever visible at ``path``: a crash or an exception inside the
    ``with`` block removes the temporary file and leaves ``path`` as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f"{TEMP_PREFIX}{path.name}.", suffix=suffix or ".tmp", dir=path.parent)
    os.close(fd)
    # mkstemp creates the file 0600; give the result the permissions a plain open() would.
    os.chmod(tmp, 0o666 & ~_UMASK)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


MAX_JSON_DEPTH = 64
"""Deepest nesting of arrays and objects :func:`loads_untrusted_json` accepts (our files
nest 6 deep; Python's parser recurses and dies of a ``RecursionError`` near 1,000)."""

_JSON_STRING = None


def json_depth(text: str) -> int:
    """The deepest nesting of ``[``/``{`` in JSON ``text`` (brackets inside strings ignored)."""

    global _JSON_STRING
    if _JSON_STRING is None:
        _JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.S)
    structure = np.frombuffer(_JSON_STRING.sub("", text).encode("utf-8", "replace"), np.uint8)
    step = np.zeros(structure.shape, np.int64)
    step[(structure == ord("[")) | (structure == ord("{"))] = 1
    step[(structure == ord("]")) | (structure == ord("}"))] = -1
    return int(np.cumsum(step).max(initial=0))


def _float_sized_int(text: str) -> int:
    value = int(text)
    try:
        float(value)
    except OverflowError:
        raise BadInput(f"the integer {text[:20]}... does not fit a float") from None
    return value


def _finite_float(text: str) -> float:
    value = float(text)
    if not np.isfinite(value):  # 1e999 parses to infinity
        raise BadInput(f"the number {text[:20]} does not fit a float")
    return value


def _no_constant(name: str):
    raise BadInput(f"{name} is not a number JSON allows")


def loads_untrusted_json(text: str | bytes, max_depth: int = MAX_JSON_DEPTH):
    """Parse JSON that someone else may have written: a ValueError (never a RecursionError or
    an OverflowError later) for nesting deeper than ``max_depth``, integers that do not fit a
    float, and NaN/Infinity."""
    if isinstance(text, bytes):
        text = text.decode("utf-8")
    depth = json_depth(text)
    if depth > max_depth:
        raise BadInput(f"JSON nested {depth} deep; at most {max_depth} is accepted")
    return json.loads(text, parse_int=_float_sized_int, parse_float=_finite_float, parse_constant=_no_constant)


def read_regular_file(path: str | os.PathLike, max_bytes: int, follow_links: bool = True) -> bytes:
    """The bytes of ``path`` if it is a regular file of at most ``max_bytes``; a ValueError
    otherwise. Never blocks on a fifo, never reads a device, reads at most ``max_bytes + 1``
    bytes whatever the file claims; with ``follow_links=False`` a symbolic link is refused."""

    flags = os.O_RDONLY | os.O_NONBLOCK | (0 if follow_links else os.O_NOFOLLOW)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        if not follow_links and os.path.islink(path):
            raise BadInput(f"{str(path)!r} is a symbolic link; only regular files are read") from None
        raise BadInput(f"cannot read {str(path)!r}: {exc.strerror or exc}") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            kind = "a folder" if stat.S_ISDIR(mode) else "not a regular file"
            raise BadInput(f"{str(path)!r} is {kind}")
        chunks, total = [], 0
        while total <= max_bytes:
            chunk = os.read(fd, min(1 << 20, max_bytes + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
    finally:
        os.close(fd)
    if total > max_bytes:
        raise BadInput(f"{str(path)!r} has more than {max_bytes:,} bytes")
    return b"".join(chunks)


def read_json_object(path: str | os.PathLike, max_bytes: int = 1 << 20, what: str = "file",
                     follow_links: bool = True) -> dict:
    """The JSON object in the file at ``path``, read as a file someone else may have made: a
    regular file of at most ``max_bytes``, parsed by :func:`loads_untrusted_json` (depth,
    integer and NaN limits), and an object at the top. Anything else is a :class:`BadInput`
    naming ``what`` and the file (never a ``RecursionError``, ``AttributeError`` or
    ``TypeError`` later)."""
    return parse_untrusted_json_object(read_regular_file(path, max_bytes, follow_links=follow_links),
                                       f"{what} {str(path)!r}")


def parse_untrusted_json_object(text: str | bytes, what: str) -> dict:
    """:func:`read_json_object` for JSON text already in hand (an archive's member, a
    header): an object at the top, within the limits, or a :class:`BadInput` naming ``what``."""
    try:
        value = loads_untrusted_json(text)
    except (ValueError, UnicodeDecodeError) as exc:
        raise BadInput(f"{what} is not valid JSON: {exc}") from None
    if not isinstance(value, dict):
        raise BadInput(f"{what} must be a JSON object, not a {type(value).__name__}")
    return value


def parse_json_object(text: str | None, name: str) -> dict:
    """Parse a command-line option holding a JSON object (empty -> ``{}``); a ValueError
    naming the option otherwise."""
    if not text:
        return {}
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise BadInput(f"{name} must be a JSON object, got {text!r} ({exc})") from None
    if not isinstance(value, dict):
        raise BadInput(f"{name} must be a JSON object, got {text!r}")
    return value


SEED_MAX = 2**63 - 1


def check_seed(seed, name: str = "seed", upper: int = SEED_MAX, allow_none: bool = True):
    """``seed`` as an int in ``[0, upper]`` (or None when allowed); a TypeError/ValueError
    naming ``name`` otherwise (numpy's own message does not say which argument was bad)."""
    if seed is None and allow_none:
        return None
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise BadInputType(f"{name} must be an int in [0, {upper}], got {seed!r}")
    if not 0 <= int(seed) <= upper:
        raise BadInput(f"{name} must be an int in [0, {upper}], got {seed!r}")
    return int(seed)


def check_reset_options(options, known=()) -> dict:
    """``reset(options=...)``: None or a dict (anything else is a TypeError). Keys the env does
    not know are warned about by name, not refused: PettingZoo's own API test resets with
    ``options={"options": 1}`` and requires envs to accept it."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise BadInputType(f"reset options must be a dict or None, got {type(options).__name__} {options!r}")
    unknown = sorted(str(k) for k in options if k not in known)
    if unknown:
        warnings.warn(f"reset option(s) {unknown} are not used: this env knows {sorted(known) or 'none'} (GS options "
                      "such as item_lifetime or grid are given when the env is made)", UserWarning, stacklevel=3)
    return dict(options)


def check_output_file(path, option: str = "--out") -> Path:
    """Check, before any long work, that a file can be written at ``path``: not a folder, and
    its folder exists (or can be made) and is writable. A ValueError naming ``option``."""
    path = Path(path)
    if path.is_dir():
        raise BadInput(f"{option} {str(path)!r} is a folder; give a file name")
    parent = path.parent if str(path.parent) else Path(".")
    existing = parent
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise BadInput(f"{option} {str(path)!r}: {str(existing)!r} is not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise BadInput(f"{option} {str(path)!r}: cannot write in {str(existing)!r}")
    if path.exists() and not os.access(path, os.W_OK):
        raise BadInput(f"{option} {str(path)!r} exists and is not writable")
    return path


def remove_stale_temporaries(folder, max_age_seconds: float = 3600.0) -> int:
    """Remove the temporary files :func:`atomic_path` leaves behind when a process is killed
    mid-write (``.<name>.<random>.tmp`` and the like) older than ``max_age_seconds`` in
    ``folder``; returns how many. Younger ones may belong to a write still under way."""

    folder = Path(folder)
    if not folder.is_dir():
        return 0
    now, removed = time.time(), 0
    for p in folder.glob(f"{TEMP_PREFIX}*"):
        with contextlib.suppress(OSError):
            if p.is_file() and now - p.stat().st_mtime > max_age_seconds:
                p.unlink()
                removed += 1
    return removed


def format_seconds(seconds: float, hour_decimals: int = 1) -> str:
    """``42 s``, ``3.5 min`` or ``2.1 h`` (hours with ``hour_decimals`` decimals)."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.{hour_decimals}f} h"
