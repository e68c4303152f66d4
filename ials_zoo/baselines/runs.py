"""A training run's folder: what is in it, whether it is finished, and how to resume it.

Every baseline writes into one folder (``--out-dir``)::

    status.json        {"state": "running" | "finished" | "failed" | "interrupted", ...}
    progress.csv       training metrics (episode return, losses, entropy, ...) per stretch of
                       training between evaluations and checkpoints
    agent_returns.csv  (runs of several agents) each agent's own mean episode return per
                       stretch: which agent's return moves when the mean does
    curve.json         the GS learning curve (steps, wall-clock, score, CI)
    checkpoint.pt      resumable training state: everything the run's future depends on
                       (weights, optimiser, random streams, episodes; tensors and plain
                       containers only: read back with ``torch.load(weights_only=True)``)
    checkpoint.json    the run's counters, curve and clock at that checkpoint
    policy.safetensors the final policy (:mod:`ials_zoo.policy`): what results point to
    result.json        the leaderboard result of the final policy (sampled actions, unless the
                       run was asked to evaluate deterministically)
    result_deterministic.json  the same policy scored with its most likely actions

A folder that already holds a run is refused, unless the caller asks to ``resume`` it (from
its last checkpoint, same settings) or to ``overwrite`` it (everything in it is removed
first). A run killed without a chance to write ``status.json`` stays ``"running"`` with a pid
that no longer exists: :func:`run_state` reports it as ``"killed"``. Every file is written
atomically, so a crash never leaves half a file.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import shutil
import socket
import sys
import time
import uuid
from pathlib import Path

from ials_zoo.errors import BadInput
from ials_zoo.utils import atomic_path, atomic_write_text, read_json_object, remove_stale_temporaries

STATUS = "status.json"
STATUS_MAX_BYTES = 1 << 20
CHECKPOINT_INFO_MAX_BYTES = 64 << 20  # the curve, and a learner's episodes in progress
LOCK = ".lock"
DETERMINISTIC_RESULT = "result_deterministic.json"
FINISHED, RUNNING, FAILED, INTERRUPTED, KILLED = "finished", "running", "failed", "interrupted", "killed"


def _pid_alive(pid) -> bool:
    try:
        os.kill(int(pid), 0)
    except (OSError, ValueError, TypeError):
        return False
    return True


def run_state(folder) -> str | None:
    """``None`` (no run here), ``finished``, ``running`` (a live process writes it),
    ``killed`` (it says running, but its process is gone), ``failed`` or ``interrupted``."""
    path = Path(folder) / STATUS
    if not path.is_file():
        return None
    try:
        status = read_json_object(path, STATUS_MAX_BYTES, what="run status")
    except (OSError, ValueError):
        return FAILED
    state = status.get("state")
    if state == RUNNING and (status.get("host") != socket.gethostname() or not _pid_alive(status.get("pid"))):
        return KILLED
    return state


class RunFolder:
    """Claims ``path`` for a run (see the module docstring).

    Args:
        path: the folder.
        resume: continue the run found there (its settings must equal ``settings``).
        overwrite: remove whatever is there first.
        settings: the run's settings (JSON-able), kept in ``status.json`` so that a resume with
            other settings is refused.
    """

    def __init__(self, path, resume: bool = False, overwrite: bool = False, settings: dict | None = None):
        if resume and overwrite:
            raise BadInput("choose one of resume and overwrite")
        self.path = Path(path)
        self.run_id = None  # set by _open: this run's, or the resumed run's
        self.settings = json.loads(json.dumps(settings or {}, default=str))
        if self.path.exists() and not self.path.is_dir():
            raise BadInput(f"--out-dir {str(self.path)!r} is a file, not a folder")
        self._lock_fd = None
        self._claim()
        try:
            self._open(resume, overwrite)
        except BaseException:
            self.release()
            raise

    def _claim(self) -> None:
        """Hold an exclusive lock on ``<folder>/.lock`` (flock, with this process's pid in it)
        for the run's life: a second run on the same folder is refused at once, and the lock
        dies with the process however it dies."""

        self._created = not self.path.exists()
        self._had_lock = (self.path / LOCK).exists()
        self.path.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 64).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise BadInput(f"{self.path} is in use by another run (pid {holder}); use another --out-dir") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._lock_fd = fd

    def release(self) -> None:
        """Give the folder up (at the end of :meth:`running`; a dead process gives it up too)."""
        if self._lock_fd is not None:
            os.close(self._lock_fd)
            self._lock_fd = None

    def _open(self, resume: bool, overwrite: bool) -> None:
        state = run_state(self.path)
        used = self.path.is_dir() and any(not p.name.startswith(".") for p in self.path.iterdir())
        self.resuming = False
        if state == RUNNING:
            raise BadInput(f"{self.path} is in use by a run that is still going (pid "
                             f"{self._status().get('pid')}); use another --out-dir")
        if resume:
            if state is None:
                raise BadInput(f"nothing to resume in {self.path}: it holds no run")
            if state == FINISHED:
                raise BadInput(f"{self.path} holds a finished run; nothing to resume")
            if not ((self.path / "checkpoint.pt").exists() and (self.path / "checkpoint.json").exists()):
                # refused before the status is touched: the folder still says what happened to it
                raise BadInput(f"{self.path} holds a run that was {state} before its first checkpoint: there is "
                               "nothing to resume; start it again with --overwrite")
            old = self._status().get("settings", {})
            if old != self.settings:
                diff = sorted(k for k in set(old) | set(self.settings) if old.get(k) != self.settings.get(k))
                raise BadInput(f"cannot resume {self.path} with other settings ({', '.join(diff)})")
            self.resuming = True
            self.run_id = self._status().get("run_id")  # None: a run from before checkpoints were bound
        elif used:
            what = f"a {state} run" if state else "files"
            if not overwrite:
                raise BadInput(f"{self.path} already holds {what}; pass --resume to continue it or "
                                 "--overwrite to replace it, or use another --out-dir")
            for p in self.path.iterdir():  # all but the lock this run holds
                if p.name != LOCK:
                    shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
        self.path.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(self.path, max_age_seconds=0)
        self._before = {p.name for p in self.path.iterdir()} - {LOCK}  # what a discarded new run leaves alone
        if not self.resuming:
            self.run_id = uuid.uuid4().hex
        self._started = time.time()
        self.set_state(RUNNING)

    def _status(self) -> dict:
        try:
            return read_json_object(self.path / STATUS, STATUS_MAX_BYTES, what="run status")
        except (OSError, ValueError):
            return {}

    def set_state(self, state: str, **extra) -> None:
        status = {"state": state, "pid": os.getpid(), "host": socket.gethostname(),
                  "command": " ".join(sys.argv), "started": self._started, "updated": time.time(),
                  "settings": self.settings, "run_id": self.run_id, **extra}
        atomic_write_text(self.path / STATUS, json.dumps(status, indent=2, default=str) + "\n")

    def binding(self) -> dict:
        """What ties a checkpoint to this run: its id (made when the folder was claimed for a
        new run, kept by every resume) and a digest of its settings (seed included).
        :func:`check_binding` refuses a checkpoint whose binding is another's."""
        digest = hashlib.sha256(json.dumps(self.settings, sort_keys=True).encode()).hexdigest()
        return {"run_id": self.run_id, "settings_sha256": digest, "seed": self.settings.get("seed")}

    @contextlib.contextmanager
    def running(self):
        """Mark the run finished when the block ends normally, interrupted on Ctrl-C/SIGTERM,
        failed on an error. Bad input found before the new run's first checkpoint (an option
        the GS refuses, an AIP set that does not fit) leaves no run behind: the folder is as
        if never claimed, so that the corrected command needs no ``--overwrite``."""
        try:
            yield self
        except KeyboardInterrupt:
            self.set_state(INTERRUPTED)
            raise
        except BadInput as exc:
            if self.resuming or (self.path / "checkpoint.json").exists():
                self.set_state(FAILED, error=f"{type(exc).__name__}: {exc}")
            else:
                self._discard()
            raise
        except BaseException as exc:
            self.set_state(FAILED, error=f"{type(exc).__name__}: {exc}")
            raise
        else:
            self.set_state(FINISHED)
        finally:
            self.release()

    def _discard(self) -> None:
        """Remove what this new run wrote, and nothing that was there before it (the folder
        too, if the claim made it)."""
        for p in self.path.iterdir():
            if p.name != LOCK and p.name not in self._before:
                shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
        if not self._had_lock:
            with contextlib.suppress(FileNotFoundError):
                (self.path / LOCK).unlink()  # before the lock is given up: no one else holds this file
        self.release()
        if self._created:
            with contextlib.suppress(OSError):
                self.path.rmdir()


class Clock:
    """Training wall-clock that excludes the time spent evaluating and checkpointing.

    ``offset`` (the AIP's collection + training seconds, or the seconds of a resumed run) is
    added; inside ``with clock.pause():`` the clock stands still."""

    def __init__(self, offset: float = 0.0):
        self.offset = float(offset)
        self._start = time.perf_counter()
        self._paused = 0.0
        self._pause_start = None

    @contextlib.contextmanager
    def pause(self):
        if self._pause_start is not None:  # nested: already stopped
            yield
            return
        self._pause_start = time.perf_counter()
        try:
            yield
        finally:
            self._paused += time.perf_counter() - self._pause_start
            self._pause_start = None

    @property
    def seconds(self) -> float:
        now = self._pause_start if self._pause_start is not None else time.perf_counter()
        return self.offset + now - self._start - self._paused


def save_training_state(folder, state: dict, info: dict) -> None:
    """``checkpoint.pt`` (tensors and plain containers) and ``checkpoint.json`` (``info``)."""
    import torch

    folder = Path(folder)
    with atomic_path(folder / "checkpoint.pt", suffix=".pt") as tmp:
        torch.save(state, tmp)
    atomic_write_text(folder / "checkpoint.json", json.dumps(info, indent=2, default=str) + "\n")


def load_training_state(folder) -> tuple[dict, dict]:
    """``(state, info)`` saved by :func:`save_training_state`, read without unpickling code."""
    import torch

    folder = Path(folder)
    try:
        state = torch.load(folder / "checkpoint.pt", map_location="cpu", weights_only=True)
        info = read_json_object(folder / "checkpoint.json", CHECKPOINT_INFO_MAX_BYTES, what="checkpoint")
    except FileNotFoundError:
        raise BadInput(f"{folder} has no checkpoint to resume from (the run ended before its first one): start it "
                       "again with --overwrite") from None
    except Exception as exc:
        raise BadInput(f"{folder}: the checkpoint cannot be read ({type(exc).__name__}: {exc})") from None
    return state, info


def check_binding(folder, state: dict, info: dict, binding: dict) -> None:
    """Refuse a checkpoint that is not this run's (``binding``: :meth:`RunFolder.binding`):
    files copied from another run's folder (another seed, other settings), or a
    ``checkpoint.pt`` and a ``checkpoint.json`` of two runs. A run from before checkpoints
    were bound (its status has no run id) resumes from an unbound checkpoint as before."""
    theirs, tensor_id = info.get("run"), state.pop("run_id", None)
    if binding["run_id"] is None and theirs is None and tensor_id is None:
        return
    if not isinstance(theirs, dict) or theirs.get("run_id") != binding["run_id"] or tensor_id != binding["run_id"]:
        whose = theirs.get("seed") if isinstance(theirs, dict) else None
        seed = f" (written by a run of seed {whose!r}; this run's seed is {binding['seed']!r})" if whose != binding["seed"] else ""
        raise BadInput(f"{folder}: the checkpoint belongs to another run{seed}: its run id "
                       f"{(theirs or {}).get('run_id') if isinstance(theirs, dict) else None!r} in checkpoint.json and "
                       f"{tensor_id!r} in checkpoint.pt, this folder's run is {binding['run_id']!r}; a checkpoint "
                       "resumes only the run that wrote it (start this one again with --overwrite)")
    if theirs.get("settings_sha256") != binding["settings_sha256"]:
        raise BadInput(f"{folder}: the checkpoint was written with other settings than this run's; it cannot resume it")


__all__ = [
    "check_binding",
    "Clock",
    "RunFolder",
    "load_training_state",
    "run_state",
    "save_training_state",
]
