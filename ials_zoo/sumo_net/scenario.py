"""What one ``sumo_net_v0`` episode simulates: the files, the hour, and RESCO's timing.

A :class:`Scenario` comes from one of RESCO's eight maps by name (read from the ``sumo-rl``
wheel, a dependency: the map files are not ours to copy), from a grid of any size by name
(``gridRxC``, generated at first use: :func:`generated_grid`), from a ``.sumocfg``, or from a
``net_file`` with its ``route_files``. Every path and time is checked here, before SUMO starts.

RESCO's settings (Pi-Star-Lab/RESCO ``config/map_config.py`` and each map's ``.sumocfg``): one
decision every 10 s with a 3 s yellow (arterial4x4: 5 s and 2 s); Cologne runs 25,200-28,800 s,
Ingolstadt 57,600-61,200 s, the grids 0-3,600 s. Two known differences of sumo-rl 1.4.5's files
from RESCO's: its ingolstadt7 and ingolstadt21 nets comment out one green phase (25 s) of one
junction (``cluster_306484187_cluster_1200363791_1200363826_1200363834_1200363898_1200363927_1200363938_1200363942``:
3 green actions there, 4 in RESCO), and it ships only the first of grid4x4's and arterial4x4's
per-episode route files (RESCO draws a new file each episode; here every episode uses ``_1``
with its own SUMO seed).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.sumo_net.names import DEFAULT_NET
from ials_zoo.utils import read_regular_file

MAX_CONFIG_BYTES = 1 << 20  # a .sumocfg is a few hundred bytes
SUMOCFG_KEYS = ("net-file", "route-files", "begin", "end")


@dataclass(frozen=True)
class Scenario:
    """One network and its demand over ``[begin, end)`` seconds, with RESCO's timing.

    Attributes:
        name: the map's name, or the file stem of a network of your own.
        net_file, route_files: absolute paths.
        begin, end: simulated seconds; the episode ends when SUMO's clock reaches ``end``.
        decision_seconds: simulated seconds between two decisions (RESCO's ``step_length``).
        yellow_seconds: the yellow inserted when a light changes its green (RESCO's
            ``yellow_length``), part of the decision interval.
    """

    name: str
    net_file: str
    route_files: tuple[str, ...]
    begin: int
    end: int
    decision_seconds: int = 10
    yellow_seconds: int = 3

    @property
    def decisions(self) -> int:
        """Decisions per episode."""
        return -(-(self.end - self.begin) // self.decision_seconds)


# name -> (begin, end, decision, yellow, route file name); RESCO's map_config.py
RESCO_MAPS = {
    "grid4x4": (0, 3600, 10, 3, "grid4x4_1.rou.xml"),
    "arterial4x4": (0, 3600, 5, 2, "arterial4x4_1.rou.xml"),
    "cologne1": (25200, 28800, 10, 3, "cologne1.rou.xml"),
    "cologne3": (25200, 28800, 10, 3, "cologne3.rou.xml"),
    "cologne8": (25200, 28800, 10, 3, "cologne8.rou.xml"),
    "ingolstadt1": (57600, 61200, 10, 3, "ingolstadt1.rou.xml"),
    "ingolstadt7": (57600, 61200, 10, 3, "ingolstadt7.rou.xml"),
    "ingolstadt21": (57600, 61200, 10, 3, "ingolstadt21.rou.xml"),
}


GRID_NAME = re.compile(r"grid(\d+)x(\d+)")
GRID_SIDES = (2, 20)  # rows and columns of a generated grid: up to 400 lights


def generated_grid(net: str) -> tuple[str, list[str]] | None:
    """``gridRxC`` (not one of RESCO's maps): a grid of R x C lights, built at first use and
    cached (:func:`ials_zoo.traffic.network.build_grid`: DIALS's grid, 100 m single-lane roads,
    a vehicle entering at every fringe road with probability 0.1 each second, routes of fewest
    turns), as ``(net file, [route file])``; None for another name."""
    match = GRID_NAME.fullmatch(str(net))
    if match is None or net in RESCO_MAPS:
        return None
    rows, cols = int(match[1]), int(match[2])
    low, high = GRID_SIDES
    if not (low <= rows <= high and low <= cols <= high):
        raise BadInput(f"net {net!r}: a generated grid has {low} to {high} rows and columns")
    from ials_zoo.traffic.network import build_grid  # lazy: netconvert builds it once, at first use

    files = build_grid((rows, cols), max_side=high)
    return files.net, [files.routes]


def resco_map_folder(name: str) -> Path:
    """The folder of RESCO map ``name`` inside the installed ``sumo-rl`` wheel (found without
    importing sumo_rl, whose import needs ``SUMO_HOME`` and pulls its own env)."""
    spec = importlib.util.find_spec("sumo_rl")
    if spec is None or not spec.submodule_search_locations:
        raise BadInput("RESCO's maps come from the sumo-rl package: pip install 'sumo-rl==1.4.5'")
    folder = Path(next(iter(spec.submodule_search_locations))) / "nets" / "RESCO" / name
    if not folder.is_dir():
        raise BadInput(f"the installed sumo-rl has no RESCO map {name!r} (expected {folder})")
    return folder


def _existing(path, flag: str) -> str:
    p = Path(os.path.expanduser(str(path)))
    if not p.is_file():
        raise BadInput(f"{flag}: no such file {str(path)!r}")
    return str(p.resolve())


def _read_sumocfg(path: str) -> dict:
    """net-file, route-files, begin and end of a ``.sumocfg`` (relative paths resolved)."""
    text = read_regular_file(path, MAX_CONFIG_BYTES)
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise BadInput(f"sumocfg: {path} is not valid XML ({e})") from None
    dropped = sorted({el.tag for el in root.iter() if len(el) == 0 and el.tag not in SUMOCFG_KEYS})
    if dropped:
        raise BadInput(f"sumocfg: {path} sets {', '.join(dropped)}, which this env would ignore (it reads only "
                       f"{', '.join(SUMOCFG_KEYS)}); give the network as net_file= and route_files= instead")
    out = {}
    for key in ("net-file", "route-files", "begin", "end"):
        node = root.find(f".//{key}")
        if node is not None and node.get("value") is not None:
            out[key] = node.get("value")
    base = Path(path).parent
    if "net-file" in out:
        out["net-file"] = str(base / out["net-file"])
    if "route-files" in out:
        out["route-files"] = [str(base / r.strip()) for r in out["route-files"].split(",") if r.strip()]
    return out


def _seconds(value, flag: str) -> int:
    try:
        f = float(value)
    except (TypeError, ValueError):
        raise BadInput(f"{flag} must be a number of seconds, got {value!r}") from None
    if not 0 <= f < 1e9 or f != int(f):  # the range first: NaN and inf fail it before int() would raise
        raise BadInput(f"{flag} must be whole seconds in [0, 1e9), got {value!r}")
    return int(f)


def _timing(begin, end, decision, yellow) -> tuple[int, int, int, int]:
    begin, end = _seconds(begin, "begin"), _seconds(end, "end")
    decision, yellow = _seconds(decision, "decision_seconds"), _seconds(yellow, "yellow_seconds")
    if begin >= end:
        raise BadInput(f"begin ({begin} s) must come before end ({end} s)")
    if decision < 1:
        raise BadInput(f"decision_seconds must be at least 1, got {decision}")
    if yellow >= decision:
        raise BadInput(f"yellow_seconds ({yellow}) must be shorter than decision_seconds ({decision})")
    return begin, end, decision, yellow


def make_scenario(net=None, sumocfg=None, net_file=None, route_files=None, begin=None, end=None,
                  decision_seconds=None, yellow_seconds=None) -> Scenario:
    """The :class:`Scenario` of a RESCO map (``net``), a ``sumocfg``, or ``net_file`` +
    ``route_files``; ``begin``/``end``/timing override the map's or the file's."""
    given = [k for k, v in (("net", net), ("sumocfg", sumocfg), ("net_file", net_file)) if v is not None]
    if len(given) != 1:
        raise BadInput("name exactly one network: net=<RESCO map> (one of "
                       f"{', '.join(RESCO_MAPS)}), sumocfg=PATH, or net_file=PATH with route_files=; got "
                       f"{', '.join(given) or 'none'}")
    if route_files is not None and net_file is None:
        raise BadInput("route_files go with net_file= (a map or a sumocfg names its own)")
    decision, yellow = 10, 3
    grid = generated_grid(net) if net is not None else None
    if grid is not None:
        name, (net_path, route_paths), b, e = net, grid, 0, 3600
    elif net is not None:
        if net not in RESCO_MAPS:
            raise BadInput(f"unknown map {net!r}; expected one of {', '.join(RESCO_MAPS)}, or a generated grid "
                           "gridRxC (or sumocfg=PATH / net_file=PATH for a network of your own: --env-options "
                           "'{\"sumocfg\": PATH}' on the command line, demo --sumocfg PATH)")
        b, e, decision, yellow, routes = RESCO_MAPS[net]
        folder = resco_map_folder(net)
        name, net_path, route_paths = net, str(folder / f"{net}.net.xml"), [str(folder / routes)]
    elif sumocfg is not None:
        cfg = _read_sumocfg(_existing(sumocfg, "sumocfg"))
        if "net-file" not in cfg:
            raise BadInput(f"sumocfg: {sumocfg} names no net-file")
        name = Path(sumocfg).name.split(".")[0]
        net_path = _existing(cfg["net-file"], f"sumocfg {sumocfg}: net-file")
        route_paths = [_existing(r, f"sumocfg {sumocfg}: route-files") for r in cfg.get("route-files", [])]
        b, e = cfg.get("begin", 0), cfg.get("end", 3600)
    else:
        name = Path(net_file).name.split(".")[0]
        net_path = _existing(net_file, "net_file")
        routes = [route_files] if isinstance(route_files, (str, os.PathLike)) else list(route_files or [])
        route_paths = [_existing(r, "route_files") for r in routes]
        b, e = 0, 3600
    if not route_paths:
        raise BadInput(f"{name}: no route files, so no traffic; give route_files= (or route-files in the sumocfg)")
    begin, end, decision, yellow = _timing(b if begin is None else begin, e if end is None else end,
                                           decision if decision_seconds is None else decision_seconds,
                                           yellow if yellow_seconds is None else yellow_seconds)
    return Scenario(name, net_path, tuple(route_paths), begin, end, decision, yellow)


__all__ = ["GRID_NAME", "RESCO_MAPS", "Scenario", "generated_grid", "make_scenario", "resco_map_folder"]


def scenario_of(net=None, sumocfg=None, net_file=None, route_files=None, begin=None, end=None,
                decision_seconds=None, yellow_seconds=None, max_cycles=None):
    """The :class:`~ials_zoo.sumo_net.scenario.Scenario` the options name (no network named:
    RESCO's cologne8); ``max_cycles`` decisions, if given, set the end."""
    if net is None and sumocfg is None and net_file is None:
        net = DEFAULT_NET
    scenario = make_scenario(net, sumocfg, net_file, route_files, begin, end, decision_seconds, yellow_seconds)
    if max_cycles is None:
        return scenario
    if isinstance(max_cycles, bool) or not isinstance(max_cycles, (int, np.integer)) or max_cycles < 1:
        raise BadInput(f"max_cycles must be an int >= 1 (decisions per episode), got {max_cycles!r}")
    if end is not None:
        raise BadInput("give end or max_cycles, not both")
    return dataclasses.replace(scenario, end=scenario.begin + int(max_cycles) * scenario.decision_seconds)
