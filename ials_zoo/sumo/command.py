"""The SUMO command line and the start/close of a libsumo simulation, shared by every SUMO domain."""

from __future__ import annotations

import os
import sys
import tempfile

from ials_zoo.sumo.lease import SimulationError

LOAD_SECONDS_BASE = 10.0
LOAD_SECONDS_PER_MIB = 1.0
"""A network's load budget (:func:`load_budget`): SUMO loaded a 230 MB netgenerate grid in 36 s
(0.16 s per MB on quiet cores); 1 s per MiB leaves room for loaded cores (2-4x slower)."""
MAX_ERROR_BYTES = 64 << 10


def sumo_binary() -> str:
    """Path of the ``sumo`` binary of the ``eclipse-sumo`` wheel (``import sumo`` sets
    ``SUMO_HOME``); plain ``"sumo"`` where the wheel gives none (libsumo ignores argv[0])."""
    import sumo

    # the wheel's own home first: another package may point SUMO_HOME at its data alone
    for home in (getattr(sumo, "SUMO_HOME", ""), os.environ.get("SUMO_HOME", "")):
        path = os.path.join(home, "bin", "sumo")
        if home and os.path.isfile(path):
            return path
    return "sumo"


def sumo_command(seed: int, *, net: str | None = None, routes=(), additionals=(), config: str | None = None,
                 extra=()) -> list[str]:
    """``sumo`` with the zoo's fixed options: 1 s steps, ``--seed seed``, no console logs.

    Either a ``config`` (a ``.sumocfg``, whose own net, routes and times apply unless ``extra``
    overrides them) or a ``net`` with its ``routes``; ``additionals`` and ``extra`` are appended.
    """
    cmd = ["sumo"]
    if config is not None:
        cmd += ["-c", str(config)]
    if net is not None:
        cmd += ["-n", str(net)]
    routes = [routes] if isinstance(routes, str) else list(routes)
    if routes:
        cmd += ["-r", ",".join(map(str, routes))]
    if additionals:
        cmd += ["-a", ",".join(map(str, additionals))]
    cmd += [
        "--step-length", "1", "--seed", str(int(seed)), "--no-step-log", "true",
        "--no-warnings", "true", "--duration-log.disable", "true", *map(str, extra),
    ]  # fmt: skip
    return cmd


def close_any_simulation(core) -> None:
    """Close the core's simulation (``core.ls`` is libsumo, ``core.running`` its flag) before a
    fresh start, also one that a SUMO error left half-closed (loaded but no longer running)."""
    if core.running or core.ls.simulation.isLoaded():
        core.running = False
        try:
            core.ls.close()
        except Exception:
            pass


def load_budget(*paths) -> float:
    """Seconds SUMO may take to load the files at ``paths`` (a network, its route files)."""
    size = 0
    for path in paths:
        try:
            size += os.path.getsize(path)
        except (OSError, TypeError):
            pass
    return LOAD_SECONDS_BASE + LOAD_SECONDS_PER_MIB * size / 2**20


def start_simulation(ls, command: list[str]) -> None:
    """``ls.start(command)`` with SUMO's own error lines in the exception: libsumo raises only
    ``Process Error`` and writes the reason (``Error: Attribute 'to' is missing ...``) to file
    descriptor 2, which in a worker is a terminal the user may not see. What SUMO writes while
    it loads is caught and, when the start succeeds, passed on to stderr."""
    failed = None
    with tempfile.TemporaryFile() as caught:
        sys.stderr.flush()
        saved = os.dup(2)
        try:  # Ctrl-C at any point in here still gives fd 2 back
            os.dup2(caught.fileno(), 2)
            ls.start(command)
        except Exception as exc:
            if not type(exc).__module__.startswith("libsumo"):
                raise  # not SUMO's: a bug of ours, as it is
            failed = exc
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        caught.seek(0)
        text = caught.read(MAX_ERROR_BYTES).decode("utf-8", "replace")
    if failed is not None:
        errors = [line for line in text.splitlines() if line.startswith("Error")]
        said = "; ".join(errors[:3]) + (f" (and {len(errors) - 3} more)" if len(errors) > 3 else "")
        raise SimulationError(f"SUMO could not start: {said or failed}") from failed
    if text:
        sys.stderr.write(text)


__all__ = ["close_any_simulation", "load_budget", "start_simulation", "sumo_binary", "sumo_command"]
