"""Starting a child interpreter and reading a process's state: what :mod:`ials_zoo.runtime.processes`
and :mod:`ials_zoo.runtime.zygote` share."""

from __future__ import annotations

import os
import subprocess
import sys


def fresh_interpreter(module: str, fds: tuple[int, ...], extra: tuple[str, ...] = ()) -> subprocess.Popen:
    """``python -m module *fds *extra`` in its own session (a Ctrl-C at the terminal is this
    process's to handle: it closes its children), sharing only ``fds`` and the environment."""
    env = dict(os.environ)
    env.setdefault("OMP_NUM_THREADS", "1")
    return subprocess.Popen([sys.executable, "-m", module, *map(str, fds), *extra], pass_fds=fds,
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, env=env, close_fds=True,
                            start_new_session=True)


def process_state(pid: int) -> str | None:
    """The kernel's one-letter state of ``pid`` (``R``, ``S``, ``T`` stopped, ``Z`` zombie,
    ...) from ``/proc``, or None where that cannot be read."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return None


def process_cpu_ticks(pid: int) -> int | None:
    """``pid``'s CPU time so far (user + system, in clock ticks) from ``/proc``, or None where
    that cannot be read: a process that holds Python's lock in compiled code (SUMO loading a
    network) sends no heartbeat, but its CPU time grows."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return int(fields[11]) + int(fields[12])  # utime, stime: fields 14 and 15 of stat(5)
    except (OSError, IndexError, ValueError):
        return None


__all__ = ["fresh_interpreter", "process_cpu_ticks", "process_state"]
