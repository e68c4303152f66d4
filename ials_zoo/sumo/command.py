"""The SUMO command line and the start/close of a libsumo simulation, shared by every SUMO domain."""

from __future__ import annotations

import os


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


__all__ = ["close_any_simulation", "sumo_binary", "sumo_command"]
