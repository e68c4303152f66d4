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

import contextlib
import fcntl
import hashlib
import json
import math
import os
import re
import shutil
from pathlib import Path

from ials_zoo.errors import BadInput
from ials_zoo.evaluation import load_model, sha256_file
from ials_zoo.leaderboard.remeasure import MAX_REMEASURE_SECONDS, check_remeasure_cost, mismatch_text, remeasure_result
from ials_zoo.leaderboard.validate import ResultError, load_result, validate_result
from ials_zoo.policy import PolicyFileError, save_policy
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
        raise BadInput(f"no leaderboard at {str(path.resolve())!r} (no {RESULTS_SUBDIR}/ folder there); run "
                         f"from the repository root, or give --dir, or set {BOARD_ENV}")
    return path


def load_entries(directory=None, subdir: str = RESULTS_SUBDIR) -> tuple[list[tuple[Path, dict]], list[tuple[Path, str]]]:
    """``(entries, problems)``: every valid result on the board as ``(path, data)`` sorted by
    file name, and ``(path, what is wrong)`` for every file that is not one."""
    folder = Path(board_path(directory, must_exist=subdir == RESULTS_SUBDIR)) / subdir
    entries, problems = [], []
    for p in sorted(folder.glob("*.json")) if folder.is_dir() else []:
        if not FILE_NAME.fullmatch(p.name):  # it goes into the pages' links: only names we would give
            problems.append((p, "its file name holds characters outside [A-Za-z0-9._-]; the board names its files "
                                "itself (leaderboard submit)"))
            continue
        try:
            entries.append((p, load_result(p, follow_links=False)))
        except ResultError as exc:
            problems.append((p, str(exc)))
    return entries, problems


def identity(data: dict) -> str:
    """What a result evaluated: track, domain, scored agents, policies (each seed's sha256, or
    the reference policy's name, a rule's ``rule:NAME``), and the evaluation (seeds, options, deterministic)."""
    kind = data["policy"]["kind"]
    reference = f"rule:{data['policy']['name']}" if kind == "rule" else kind  # a rule by its name
    policies = sorted(s["policy_sha256"] or reference for s in data["scores"])
    ev = data["evaluation"]
    key = {"track": data["track"], "env_id": data["env_id"], "agents": data["agents"], "policies": policies,
           "seeds": ev["seeds"], "options": ev["options"], "deterministic": ev["deterministic"]}
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()


FILE_NAME = re.compile(r"[A-Za-z0-9._-]+")
"""The names of the board's files (``entry_name``): the only ones its pages link to."""


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9.-]+", "-", str(text)).strip("-")[:40] or "x"


def entry_name(data: dict) -> str:
    """The file name of a result on the board (unique by what was evaluated)."""
    sim = (data["training"] or {}).get("simulator", "none")
    sim = Path(sim).stem if sim.endswith(".pt") else sim
    who = re.sub(r"[^A-Za-z0-9._-]+", "-", data["agent"]) if data["track"] == "single-agent" else f"{len(data['agents'])}-agents"
    return "__".join([data["env_id"], who, _slug(data["algorithm"]), _slug(sim), identity(data)[:12]]) + ".json"


def _refuse_duplicate(board: Path, data: dict) -> None:
    mine = identity(data)
    for p, other in load_entries(board)[0]:
        if identity(other) == mine:
            raise ResultError("(file)", f"duplicate: {p.name} already scores the same policies of the same agents with "
                              "the same protocol")


def resolve_policy_file(spec: str, result_path: Path, board: Path | None = None) -> Path | None:
    """Where a recorded ``policy_file`` is: as given, relative to the result's folder, or
    relative to the board."""
    for candidate in (Path(spec), result_path.parent / spec, *(() if board is None else (board / spec,))):
        if candidate.is_file():
            return candidate
    return None


PROVENANCE_HEADER = "header-agrees"
PROVENANCE_EXTERNAL = "external"


def training_provenance(data: dict, networks: list) -> str:
    """Whether our trainers produced the policies of ``data``: each policy file's header holds
    the training record its trainer wrote (algorithm, seed, simulator, steps, wall-clock).
    ``"header-agrees"`` when every header has one and the result repeats it: the header and
    the result agree, and no more (whoever can write a result can write a header; what makes
    a training claim checked is ``ials-zoo leaderboard verify --retrain``, :mod:`.retrain`);
    ``"external"`` when a header has none. A header whose record
    contradicts the result is a :class:`ResultError`: the result claims another training."""
    training = data["training"] or {}
    headers = [net.metadata for net in networks]
    if not headers or any(not isinstance(h.get("training"), dict) or "algorithm" not in h for h in headers):
        return PROVENANCE_EXTERNAL
    for i, (score, h) in enumerate(zip(data["scores"], headers)):
        record = h["training"]
        claims = {"algorithm": (h["algorithm"], data["algorithm"]), "seed": (h.get("seed"), score["seed"]),
                  "training.simulator": (record.get("simulator"), training.get("simulator")),
                  "training.env_steps": (record.get("env_steps"), training.get("env_steps"))}
        if len(data["scores"]) == 1:  # a merged entry's timings are its seeds' together
            claims["training.reference"] = (record.get("reference"), training.get("reference"))
        for field, (written, claimed) in claims.items():
            if written != claimed:
                raise ResultError(f"scores.{i}", f"{field} is {claimed!r} in the result but {written!r} in the "
                                  "training record its policy file carries")
    walls = [float(h["training"].get("wall_clock_seconds", float("nan"))) for h in headers]
    claimed_wall = float(training.get("wall_clock_seconds", float("nan")))
    if not math.isclose(sum(walls) / len(walls), claimed_wall, rel_tol=1e-6, abs_tol=1e-6):
        raise ResultError("training.wall_clock_seconds", f"{claimed_wall!r} in the result, but the policy files "
                          f"record {walls} (the result's is their mean)")
    return PROVENANCE_HEADER


def _check_policies(data: dict, path: Path, board: Path) -> tuple[list, list]:
    """Resolve, hash-check and load every policy of a model result; returns ``(copies,
    networks)``: ``(source, board target)`` pairs and the loaded networks. A policy that does
    not load as a policy of the entry's domain and agents is refused; an SB3 zip is converted
    to a policy file (the board keeps weights + JSON only)."""
    copies, networks = [], []
    for i, s in enumerate(data["scores"]):
        found = resolve_policy_file(s["policy_file"], path, board)
        if found is None:
            raise ResultError(f"scores.{i}.policy_file", f"{s['policy_file']!r} not found (looked next to the "
                              "result and in the board); the board keeps every policy it scores")
        digest = sha256_file(found)
        if digest != s["policy_sha256"]:
            raise ResultError(f"scores.{i}.policy_sha256", f"{found} has sha256 {digest}, the result says "
                              f"{s['policy_sha256']}")
        try:
            policy = load_model(found, data["agent"])
        except (ValueError, PolicyFileError, OSError) as exc:
            raise ResultError(f"scores.{i}.policy_file", f"{str(found)!r} is not a policy file: {exc}") from None
        missing = [a for a in data["agents"] if a not in policy.agents]
        if policy.metadata.get("env_id") not in (None, data["env_id"]) or missing:
            raise ResultError(f"scores.{i}.policy_file", f"{str(found)!r} is a policy of "
                              f"{policy.metadata.get('env_id')!r} for {list(policy.agents)}, not of {data['env_id']!r} "
                              f"for {data['agents']}")
        networks.append(policy.net)
        if found.suffix == ".zip":
            converted = board / POLICIES_SUBDIR / f".converted-{digest}.safetensors"
            save_policy(policy.net, converted)
            digest = sha256_file(converted)
            found = converted
            s["policy_sha256"] = digest
        target = Path(POLICIES_SUBDIR) / f"{digest}.safetensors"
        copies.append((found, board / target))
        s["policy_file"] = target.as_posix()
    return copies, networks


@contextlib.contextmanager
def _board_lock(board: Path):
    """One submission at a time per board: an exclusive ``flock`` on its ``results/`` folder
    (no lock file is left behind), so that two submissions of the same evaluation cannot both
    pass the duplicate check; the lock dies with the process that holds it."""

    fd = os.open(board / RESULTS_SUBDIR, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def submit(path, directory=None, remeasure: bool = True, max_remeasure_seconds: float = MAX_REMEASURE_SECONDS) -> Path:
    """Validate the result at ``path`` and add it to the board; return its new path.

    Raises :class:`ResultError` for a malformed, inconsistent or duplicate result, for code,
    for a policy file that is missing, does not have its recorded sha256 or does not load as a
    policy of the entry, for training claims its policy files contradict, and (``remeasure``)
    for scores that the GS does not reproduce exactly; the board is left untouched in every
    failure (atomic writes, never an overwrite, one submission at a time). A re-measure whose
    estimated cost is over ``max_remeasure_seconds`` is refused before anything else."""
    path = Path(path)
    board = board_path(directory)
    results = board / RESULTS_SUBDIR
    remove_stale_temporaries(results)
    remove_stale_temporaries(board / POLICIES_SUBDIR)
    data = load_result(path)
    kind = data["policy"]["kind"]
    if kind == "callable":
        raise ResultError("policy.kind", "a callable policy is code; the board holds policy files (weights + JSON) "
                          "and reference policies only")
    if remeasure:
        check_remeasure_cost(data, max_remeasure_seconds)
    data.pop("retrained", None)  # the board's own record of a re-train, never a submitter's claim
    copies, converted = [], []
    try:
        if kind == "model":
            copies, networks = _check_policies(data, path, board)
            converted = [c for c, _ in copies if c.name.startswith(".converted-")]
            data["provenance"] = training_provenance(data, networks)
        else:
            data.pop("provenance", None)
        validate_result(data)
        _refuse_duplicate(board, data)  # before the re-measure's minutes (again under the lock below)
        if remeasure:
            reports = remeasure_result(data, [str(c) for c, _ in copies] or None, max_seconds=max_remeasure_seconds)
            bad = [r for r in reports if not r["ok"]]
            if bad:
                raise ResultError("scores", f"re-measured on the GS, {mismatch_text(bad[0])}")
        with _board_lock(board):
            _refuse_duplicate(board, data)  # one submitted meanwhile
            dest = results / entry_name(data)
            if dest.exists():
                raise ResultError("(file)", f"{dest} already exists; refusing to overwrite it")
            for source, target in copies:
                if not target.exists():
                    with atomic_path(target, suffix=target.suffix) as tmp:
                        shutil.copyfile(source, tmp)
            with atomic_path(dest) as tmp:
                tmp.write_text(json.dumps(data, indent=2, allow_nan=False) + "\n")
    finally:
        for c in converted:
            with contextlib.suppress(FileNotFoundError):
                c.unlink()
    return dest


__all__ = ["ARCHIVE_SUBDIR", "BOARD_ENV", "POLICIES_SUBDIR", "PROVENANCE_EXTERNAL", "PROVENANCE_HEADER",
           "RESULTS_SUBDIR", "board_path", "entry_name", "identity", "load_entries", "resolve_policy_file", "submit",
           "training_provenance"]
