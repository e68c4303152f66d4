"""Run the jobs of a study as subprocesses, at most ``jobs`` at once, skipping done ones.

Ready jobs start in :meth:`Job.priority` order (AIPs, then the longest runs first); an
:attr:`~ials_zoo.reproduce.plan.Job.exclusive` job (a multi-agent run, which uses every core
itself and whose wall-clock is compared) runs alone.

Every job is its own process (``python -m ials_zoo.reproduce.worker job.json``) so that each
SUMO simulation owns its process (libsumo holds one per process) and a crash loses one run
only. The job's stdout/stderr go to ``log.txt`` in its folder; the study shows one tqdm bar
over jobs. A job whose dependency failed is not started (reported as ``blocked``).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from tqdm import tqdm

from ials_zoo.errors import BadInput
from ials_zoo.reproduce.plan import Job


class StudyInUseError(RuntimeError, BadInput):
    """Another ``ials-zoo reproduce`` holds the study folder (a situation, named in one line)."""

def _signal_group(proc: subprocess.Popen, sig) -> None:
    try:
        os.killpg(proc.pid, sig)  # the job's own process group (start_new_session=True)
    except ProcessLookupError:
        pass


def _command(job_file: Path) -> list[str]:
    return [sys.executable, "-m", "ials_zoo.reproduce.worker", str(job_file)]


def run_jobs(jobs: list[Job], n_jobs: int = 2, progress: bool = True, poll: float = 0.5,
             lock_dir=None) -> dict:
    """Run the jobs not yet done, respecting ``deps``; a folder holding a job with other
    settings (:meth:`Job.conflict`) stops everything before anything runs, and so does
    another invocation running in ``lock_dir`` (default: the jobs' common folder; the study
    passes its ``--out``). Returns ``{"done": [...], "skipped": [...], "failed": [...],
    "blocked": [...]}`` (job ids)."""
    if isinstance(n_jobs, bool) or not isinstance(n_jobs, int) or n_jobs < 1:
        raise BadInput(f"n_jobs must be a positive int, got {n_jobs!r}")
    ids = {j.id for j in jobs}
    for j in jobs:
        missing = [d for d in j.deps if d not in ids]
        if missing:
            raise BadInput(f"job {j.id} depends on {missing}, which are not in the plan")
    conflicts = [f"  {j.id}: {j.conflict()}" for j in jobs if j.conflict()]
    if conflicts:
        raise BadInput("these run folders hold runs with other settings; use another --out or "
                         "remove them:\n" + "\n".join(conflicts))
    status = {j.id: ("skipped" if j.done else "pending") for j in jobs}
    if any(v == "pending" for v in status.values()):
        lock = Path(lock_dir) if lock_dir is not None else Path(os.path.commonpath([j.dir for j in jobs]))
        with study_lock(lock):
            return _run(jobs, status, n_jobs, progress, poll)
    return _summary(jobs, status)


@contextlib.contextmanager
def study_lock(folder: Path):
    """Hold ``<folder>/.reproduce.lock`` (flock) while jobs run: a second invocation on the
    same study would start the same unfinished jobs twice, so it is refused."""

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / ".reproduce.lock"
    f = open(path, "a+")
    try:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.seek(0)
            raise StudyInUseError(f"another ials-zoo reproduce is running in {folder} "
                               f"(lock {path}, held by pid {f.read().strip() or '?'})") from None
        f.seek(0)
        f.truncate()
        f.write(str(os.getpid()))
        f.flush()
        yield
    finally:
        f.close()


def _summary(jobs, status) -> dict:
    out = {k: [] for k in ("done", "skipped", "failed", "blocked")}
    for j in jobs:
        out[status[j.id]].append(j.id)
    return out


def _run(jobs, status, n_jobs, progress, poll) -> dict:
    pending = [j for j in jobs if status[j.id] == "pending"]
    running: dict[str, tuple[Job, subprocess.Popen, object, float]] = {}
    bar = None
    if progress:
        bar = tqdm(total=len(pending), desc="reproduce", unit="run", dynamic_ncols=True)
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONUNBUFFERED="1")
    try:
        while pending or running:
            for jid, (job, proc, log, t0) in list(running.items()):
                rc = proc.poll()
                if rc is None:
                    continue
                log.close()
                del running[jid]
                ok = rc == 0 and job.done
                status[jid] = "done" if ok else "failed"
                if bar is not None:
                    bar.update(1)
                    if not ok:
                        bar.write(f"FAILED {jid} (exit {rc}); see {Path(job.dir) / 'log.txt'}")
            for job in sorted(pending, key=lambda j: j.priority()):
                states = [status[d] for d in job.deps]
                if any(s in ("failed", "blocked") for s in states):
                    status[job.id] = "blocked"
                    pending.remove(job)
                    if bar is not None:
                        bar.update(1)
                        bar.write(f"BLOCKED {job.id}: a dependency failed")
                    continue
                if len(running) >= n_jobs or not all(s in ("done", "skipped") for s in states):
                    continue
                if running and (job.exclusive or any(j.exclusive for j, *_ in running.values())):
                    continue
                job_file = job.write()
                log = open(Path(job.dir) / "log.txt", "a")
                log.write(f"\n=== {time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())} {' '.join(_command(job_file))}\n")
                log.flush()
                # Own session: an interrupt can then stop the job with everything it started
                # (SUMO vec-env workers, evaluation pools) by its process group id.
                proc = subprocess.Popen(_command(job_file), stdout=log, stderr=subprocess.STDOUT, env=env,
                                        start_new_session=True)
                running[job.id] = (job, proc, log, time.perf_counter())
                pending.remove(job)
            if bar is not None:
                bar.set_postfix_str(", ".join(sorted(j.split("/", 1)[1] for j in running))[:80])
            if running:
                time.sleep(poll)
    except BaseException:
        # Interrupted: stop our own children so nothing keeps writing behind our back. Their
        # folders have no marker file, so the next invocation runs them again.
        for _, proc, log, _ in running.values():
            _signal_group(proc, signal.SIGTERM)
        for _, proc, log, _ in running.values():
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                _signal_group(proc, signal.SIGKILL)
            log.close()
        raise
    finally:
        if bar is not None:
            bar.close()
    return _summary(jobs, status)
