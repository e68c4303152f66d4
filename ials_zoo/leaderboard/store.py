"""The board on disk: where it is, what is on it, and how a result gets there.

A board is a folder (``leaderboard/`` of the repository, or ``--dir``, or
``$IALS_ZOO_LEADERBOARD``) with

* ``results/<env_id>__<who>__<algorithm>__<simulator>__<hash>.json`` -- the entries;
* ``policies/<sha256>.safetensors`` -- every policy an entry scores, copied in by
  :func:`submit`, so that anyone can re-score every entry from the board alone;
* ``archive/*.json`` -- earlier results whose policies were not kept: shown apart, never
  re-scorable, never added to by ``submit``.

:func:`submit` validates a result (:mod:`ials_zoo.leaderboard.validate`), refuses code
(``callable`` policies), checks each policy file against its recorded sha256, refuses a
result that evaluates what an entry already evaluated (same policies, agents and protocol),
copies the policy files in, and writes the entry atomically, never over an existing file.
:func:`load_entries` reads every entry; a file that is not a valid entry is reported with its
name and skipped, so one bad file never hides the rest of the board.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
from pathlib import Path

from ials_zoo.leaderboard.validate import ResultError, load_result
from ials_zoo.utils import atomic_path, remove_stale_temporaries

RESULTS_SUBDIR = "results"
POLICIES_SUBDIR = "policies"
ARCHIVE_SUBDIR = "archive"
BOARD_ENV = "IALS_ZOO_LEADERBOARD"


def board_path(directory=None, must_exist: bool = True) -> Path:
    """The board folder: ``directory``, else ``$IALS_ZOO_LEADERBOARD``, else ``./leaderboard``.
    With ``must_exist``, a ValueError saying where it looked when there is no board there."""
    if directory is None:
        directory = os.environ.get(BOARD_ENV) or "leaderboard"
    path = Path(directory)
    if must_exist and not (path / RESULTS_SUBDIR).is_dir():
        raise ValueError(f"no leaderboard at {str(path.resolve())!r} (no {RESULTS_SUBDIR}/ folder there); run "
                         f"from the repository root, or give --dir, or set {BOARD_ENV}")
    return path


def load_entries(directory=None, subdir: str = RESULTS_SUBDIR) -> tuple[list[tuple[Path, dict]], list[tuple[Path, str]]]:
    """``(entries, problems)``: every valid result on the board as ``(path, data)`` sorted by
    file name, and ``(path, what is wrong)`` for every file that is not one."""
    folder = Path(board_path(directory, must_exist=subdir == RESULTS_SUBDIR)) / subdir
    entries, problems = [], []
    for p in sorted(folder.glob("*.json")) if folder.is_dir() else []:
        try:
            entries.append((p, load_result(p)))
        except ResultError as exc:
            problems.append((p, str(exc)))
    return entries, problems


def identity(data: dict) -> str:
    """What a result evaluated: track, domain, scored agents, policies (each seed's sha256, or
    the reference policy's name), and the evaluation (seeds, options, deterministic)."""
    policies = sorted(s["policy_sha256"] or data["policy"]["kind"] for s in data["scores"])
    ev = data["evaluation"]
    key = {"track": data["track"], "env_id": data["env_id"], "agents": data["agents"], "policies": policies,
           "seeds": ev["seeds"], "options": ev["options"], "deterministic": ev["deterministic"]}
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9.-]+", "-", str(text)).strip("-")[:40] or "x"


def entry_name(data: dict) -> str:
    """The file name of a result on the board (unique by what was evaluated)."""
    sim = (data["training"] or {}).get("simulator", "none")
    sim = Path(sim).stem if sim.endswith(".pt") else sim
    who = data["agent"] if data["track"] == "single-agent" else f"{len(data['agents'])}-agents"
    return "__".join([data["env_id"], who, _slug(data["algorithm"]), _slug(sim), identity(data)[:12]]) + ".json"


def resolve_policy_file(spec: str, result_path: Path, board: Path | None = None) -> Path | None:
    """Where a recorded ``policy_file`` is: as given, relative to the result's folder, or
    relative to the board."""
    for candidate in (Path(spec), result_path.parent / spec, *(() if board is None else (board / spec,))):
        if candidate.is_file():
            return candidate
    return None


def submit(path, directory=None) -> Path:
    """Validate the result at ``path`` and add it to the board; return its new path.

    Raises :class:`ResultError` for a malformed, inconsistent or duplicate result, for code,
    and for a policy file that is missing or does not have its recorded sha256; the board is
    left untouched in every failure (atomic writes, never an overwrite)."""
    from ials_zoo.evaluation import sha256_file

    path = Path(path)
    board = board_path(directory)
    results = board / RESULTS_SUBDIR
    remove_stale_temporaries(results)
    data = load_result(path)
    if data["policy"]["kind"] == "callable":
        raise ResultError("policy.kind", "a callable policy is code; the board holds policy files (weights + JSON) "
                          "and reference policies only")
    copies = []
    for i, s in enumerate(data["scores"]):
        if data["policy"]["kind"] != "model":
            continue
        found = resolve_policy_file(s["policy_file"], path, board)
        if found is None:
            raise ResultError(f"scores.{i}.policy_file", f"{s['policy_file']!r} not found (looked next to the "
                              "result and in the board); the board keeps every policy it scores")
        digest = sha256_file(found)
        if digest != s["policy_sha256"]:
            raise ResultError(f"scores.{i}.policy_sha256", f"{found} has sha256 {digest}, the result says "
                              f"{s['policy_sha256']}")
        target = Path(POLICIES_SUBDIR) / f"{digest}{''.join(found.suffixes[-1:]) or '.safetensors'}"
        copies.append((found, board / target))
        s["policy_file"] = target.as_posix()
    entries, _ = load_entries(board)
    mine = identity(data)
    for p, other in entries:
        if identity(other) == mine:
            raise ResultError("(file)", f"duplicate: {p.name} already scores the same policies of the same agents "
                              "with the same protocol")
    dest = results / entry_name(data)
    if dest.exists():
        raise ResultError("(file)", f"{dest} already exists; refusing to overwrite it")
    for source, target in copies:
        if not target.exists():
            with atomic_path(target, suffix=target.suffix) as tmp:
                shutil.copyfile(source, tmp)
    with atomic_path(dest) as tmp:
        tmp.write_text(json.dumps(data, indent=2, allow_nan=False) + "\n")
    return dest


__all__ = ["ARCHIVE_SUBDIR", "BOARD_ENV", "POLICIES_SUBDIR", "RESULTS_SUBDIR", "board_path", "entry_name",
           "identity", "load_entries", "resolve_policy_file", "submit"]
