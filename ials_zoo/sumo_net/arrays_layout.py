"""The static arrays of the array local simulator (:mod:`ials_zoo.sumo_net.arrays`): every
region's lanes, the signals that control its links, the vehicle kinds and the routes inside it.

Read once from the network file (``sumolib``, as :mod:`ials_zoo.sumo_net.regions` reads it) and
the route files' vehicle types; nothing here changes while the simulation runs, except the
route table, which grows as new routes come in (a region's routes are those of the GS's
entries, a few hundred).

* **lanes**: every lane of every edge of every region, regions one after another (a road in two
  regions is a lane of each), with its length (m) and speed limit (m/s);
* **signals**: one row per ``(region, light)`` for the region's own light and every other light
  whose links the region's lanes use (a junction past a short exit keeps its own program).
  Each row has its phases' durations and, per phase and link index, what the link shows:
  green (``G``), minor green (``g``: it yields to the links SUMO's ``response`` names), yellow,
  red; a link no light controls is always green;
* **routes**: a vehicle's way through its region (the GS's entry tables give it) as *steps*,
  one per edge; per step the lanes a vehicle may drive on (those with a connection onto the next
  edge), for each the link it crosses and the junction's length, and where the vehicle leaves
  the region if the step is its last (:attr:`~ials_zoo.sumo_net.regions.NetRegion.exits`, or the
  edge's end where its way leaves the region at a junction inside it), and the next edge's
  lanes its links lead to (a vehicle keeps to them where they lead on: SUMO changes lanes only
  where it must, or where another lane is much emptier).
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.sumo_net.core import yellow_program
from ials_zoo.sumo_net.metrics import MAX_ROUTE_BYTES, iter_elements
from ials_zoo.sumo_net.regions import read_sumolib

# SUMO's defaults per vehicle class (sumo.dlr.de/docs/Vehicle_Type_Parameter_Defaults.html):
# length, minGap (m), accel, decel (m/s^2), maxSpeed (m/s), sigma (Krauss's dawdling)
KIND_DEFAULTS = {"passenger": (5.0, 2.5, 2.6, 4.5, 55.56, 0.5), "bus": (12.0, 2.5, 1.2, 4.0, 27.78, 0.5),
                 "truck": (7.1, 2.5, 1.3, 4.0, 36.11, 0.5), "delivery": (6.5, 2.5, 2.6, 4.5, 55.56, 0.5)}
KIND_FIELDS = ("length", "minGap", "accel", "decel", "maxSpeed", "sigma")
GREEN, MINOR, YELLOW, RED = 2, 3, 1, 0  # MINOR: green, yielding to the links it must
MAX_CANDIDATES = 8  # lanes of one edge a vehicle may choose between
MAX_TARGETS = 4  # lanes of the next edge one lane's links lead to
MAX_FOES = 24  # links one link yields to
MIN_SHARE = 0.02  # a lane the GS hardly used still takes a vehicle when the others are full


MAX_NET_BYTES = 512 << 20


@functools.lru_cache(maxsize=8)
def _internal_speeds(net_file: str, mtime: float) -> dict[str, float]:
    speeds = {}
    for el in iter_elements(net_file, MAX_NET_BYTES):
        if el.tag == "lane" and el.get("id", "").startswith(":"):
            speeds[el.get("id")] = float(el.get("speed"))
        elif el.tag in ("edge", "connection", "junction", "tlLogic"):
            el.clear()
    return speeds


def internal_speeds(net_file: str) -> dict[str, float]:
    """The speed limit of every internal lane (the way across a junction) of ``net_file``, by
    id: SUMO's drivers slow to it before their line (the network file sets it from the turn's
    radius). ``sumolib`` leaves internal lanes out as the regions read the network."""
    return _internal_speeds(str(net_file), os.path.getmtime(net_file))


def vehicle_kinds(route_files) -> dict[str, np.ndarray]:
    """Every ``vType`` of the route files as ``[length, minGap, accel, decel, maxSpeed, sigma]``
    (SUMO's class defaults where a field is not given); ``"DEFAULT_VEHTYPE"`` too."""
    kinds = {"DEFAULT_VEHTYPE": np.array(KIND_DEFAULTS["passenger"])}
    for f in route_files:
        for el in iter_elements(f, MAX_ROUTE_BYTES, "vType"):
            base = KIND_DEFAULTS.get(el.get("vClass", "passenger"), KIND_DEFAULTS["passenger"])
            try:
                kinds[el.get("id")] = np.array([float(el.get(k, d)) for k, d in zip(KIND_FIELDS, base)])
            except ValueError:
                raise BadInput(f"{f}: vType {el.get('id')!r} has a field that is not a number") from None
    return kinds


@dataclass
class SignalRows:
    """Every signal row (module docstring) of one copy of the regions.

    Attributes:
        names: ``(region index, light id)`` per row.
        driven: per row, whether actions drive it (RESCO's greens and yellows) or its own program runs.
        phase_start: per row, its first phase's index into ``durations``/``shows`` (``[rows + 1]``).
        durations: seconds per phase (all rows' phases one after another).
        shows: ``[phases, max links]`` GREEN/YELLOW/RED per link index.
        yellow_of: per driven row, ``(green, green) -> yellow phase`` (RESCO's ``create_yellows``).
        first_phase, first_elapsed: per row, its phase and seconds into it (less one: SUMO counts a
            phase from the step after it starts) as the simulation begins.
    """

    names: list
    driven: np.ndarray
    phase_start: np.ndarray
    durations: np.ndarray
    shows: np.ndarray
    yellow_of: list
    first_phase: np.ndarray
    first_elapsed: np.ndarray


def _show(state: str) -> list[int]:
    return [GREEN if c == "G" else MINOR if c == "g" else YELLOW if c in "yYuo" else RED for c in state]


def signal_rows(net, rows: list[tuple[int, str, bool]], yellow_seconds: int, begin: float = 0.0) -> SignalRows:
    """``rows``: ``(region index, light id, driven)``. A driven light's phases are RESCO's program
    (its greens, then the yellows), from its first; another light's are its own program 0, where
    SUMO has it at ``begin`` (:func:`program_position`)."""
    phases, yellow_of, start, first = [], [], [0], []
    for _, light, driven in rows:
        program = list(net.getTLS(light).getPrograms().values())[0]
        own = [(float(p.duration), p.state) for p in program.getPhases()]
        if driven:
            greens = [(d, s) for d, s in own if "y" not in s and "g" in s.lower()]
            yellows, index = yellow_program([s for _, s in greens], yellow_seconds)
            own = greens + yellows
            yellow_of.append(index)
            first.append((0, -1.0))
        else:
            yellow_of.append({})
            first.append(program_position([d for d, _ in own], float(program.getOffset() or 0), begin))
        phases += own
        start.append(len(phases))
    width = max(len(s) for _, s in phases)
    shows = np.full((len(phases), width), RED, np.int8)
    for k, (_, s) in enumerate(phases):
        shows[k, :len(s)] = _show(s)
    return SignalRows([(r, x) for r, x, _ in rows], np.array([d for *_, d in rows], bool), np.array(start, np.int64),
                      np.array([d for d, _ in phases], np.float64), shows, yellow_of,
                      np.array([k for k, _ in first], np.int64), np.array([e for _, e in first], np.float64))


def program_position(durations: list[float], offset: float, begin: float) -> tuple[int, float]:
    """``(phase, seconds into it less one)`` of a fixed program at ``begin``: SUMO runs a static
    program as if from time ``offset``, so a simulation that begins mid-cycle finds its lights
    mid-cycle (measured: ingolstadt21 begins at 57,600 s, 55 s into 243641585's 85 s cycle)."""
    into = (begin - offset) % sum(durations)
    ends = np.cumsum(durations)
    k = int(np.searchsorted(ends, into, side="right"))
    return k, into - (ends[k] - durations[k]) - 1.0


class RegionArrays:
    """The lanes, signals and routes of ``regions`` (light -> :class:`~ials_zoo.sumo_net.regions.NetRegion`)
    of ``net_file``, in that order (module docstring); ``driven``: the lights driven by actions
    (the IALS's learners; True: all, False: none, as in the replay); the others run their own
    program, from where SUMO has it at ``begin`` (the scenario's first second)."""

    def __init__(self, net_file: str, regions: dict, yellow_seconds: int, driven=True, begin: float = 0.0):
        driven = set(regions) if driven is True else set(driven or ())
        net = read_sumolib(net_file)
        self.regions = list(regions.values())
        self.lights = list(regions)
        self.lane_ids: list[str] = []  # "<light>__<lane>"
        self.lane_of: list[dict[str, int]] = []  # per region: lane id -> lane index
        self.edge_lanes: list[dict[str, list[int]]] = []  # per region: edge -> its lanes, by index
        lengths, speeds = [], []
        for light, region in regions.items():
            lanes, edges = {}, {}
            for e in region.edges:
                for lane in net.getEdge(e).getLanes():
                    lanes[lane.getID()] = len(self.lane_ids)
                    edges.setdefault(e, []).append(len(self.lane_ids))
                    self.lane_ids.append(f"{light}__{lane.getID()}")
                    lengths.append(lane.getLength())
                    speeds.append(lane.getSpeed())
            self.lane_of.append(lanes)
            self.edge_lanes.append(edges)
        if not self.lane_ids:
            raise BadInput("the regions have no lanes: nothing to simulate")
        self.lane_length = np.array(lengths, np.float64)
        self.lane_index = np.array([int(x.rsplit("_", 1)[1]) for x in self.lane_ids], np.int64)  # on its edge
        # each lane's share of its edge's vehicles (:mod:`ials_zoo.sumo_net.arrays_calibration`): equal until calibrated
        self.lane_share = np.ones(len(self.lane_ids))
        for per in self.edge_lanes:
            for lanes in per.values():
                self.lane_share[lanes] = 1.0 / len(lanes)
        self.lane_speed = np.array(speeds, np.float64)
        self.n_lanes = len(self.lane_ids)
        self.signals, self.links = self._signals(net, net_file, regions, yellow_seconds, driven, begin)
        self.routes = RouteTable(self)

    def calibrate(self, shares: dict[str, float]) -> None:
        """Lane shares measured in the GS (:func:`ials_zoo.sumo_net.arrays_calibration.lane_shares`),
        by the network's lane id; lanes not named keep theirs."""
        for k, x in enumerate(self.lane_ids):
            share = shares.get(x.split("__", 1)[1])
            if share is not None:
                self.lane_share[k] = min(max(float(share), MIN_SHARE), 1.0)

    def _signals(self, net, net_file: str, regions: dict, yellow_seconds: int, driven: set, begin: float):
        """The signal rows and, per region, ``(lane, next edge) ->`` :class:`Link` (its code
        ``row * width + link index``, -1 where no light controls it); sets :attr:`foes`."""
        rows, row_of, found = [], {}, []
        for r, (light, region) in enumerate(regions.items()):
            rows.append((r, light, light in driven))
            row_of[(r, light)] = len(rows) - 1
            inside, mine = set(region.edges), {}
            for e in region.edges:
                for lane in net.getEdge(e).getLanes():
                    for c in lane.getOutgoing():
                        to, tls = c.getTo().getID(), c.getTLSID()
                        if to not in inside or (lane.getID(), to) in mine:
                            continue
                        if tls and (r, tls) not in row_of:
                            rows.append((r, tls, False))
                            row_of[(r, tls)] = len(rows) - 1
                        mine[(lane.getID(), to)] = (c, row_of[(r, tls)] if tls else -1)
            found.append(mine)
        signals = signal_rows(net, rows, yellow_seconds, begin)
        turn_speed = internal_speeds(net_file)
        links, n = [], 0
        for r, mine in enumerate(found):
            coded = {}
            for (lane, to), (c, row) in mine.items():
                targets = [self.lane_of[r][x.getToLane().getID()] for x in c.getFromLane().getOutgoing()
                           if x.getTo().getID() == to]
                code = row * signals.shows.shape[1] + c.getTLLinkIndex() if row >= 0 else -1
                coded[(lane, to)] = Link(code, _junction_metres(c.getFromLane(), c.getToLane()), targets, n, c,
                                         turn_speed.get(c.getViaLaneID(), math.inf))
                n += 1
            links.append(coded)
        self.n_links = n
        self.foes = _foes(links)
        return signals, links


@dataclass
class Link:
    """A region's way from a lane onto its next edge: its signal code, the junction's metres,
    the next edge's lanes its connections lead to, its index among the regions' links and
    SUMO's connection and the speed limit across the junction (inf where the network has none)."""

    code: int
    metres: float
    targets: list
    index: int
    connection: object
    speed: float = math.inf


def _foes(links: list[dict]) -> np.ndarray:
    """``[links, MAX_FOES]``: per link, the links of its region it must yield to at its junction
    (SUMO's ``response``), -1 padded."""
    n = sum(len(x) for x in links)
    foes = np.full((n, MAX_FOES), -1, np.int64)
    for mine in links:
        by_node: dict = {}
        for x in mine.values():
            by_node.setdefault(x.connection.getJunction(), []).append(x)
        for node, these in by_node.items():
            for x in these:
                theirs = [y.index for y in these if y is not x and node.forbids(y.connection, x.connection)]
                foes[x.index, :len(theirs[:MAX_FOES])] = theirs[:MAX_FOES]
    used = int((foes >= 0).sum(axis=1).max()) if n else 0
    return foes[:, :max(used, 1)]  # as wide as the most foes of one link: every vehicle reads a row


def _junction_metres(lane, to_lane) -> float:
    """The way across the junction: from the lane's end to the next lane's start, in a line."""
    (x0, y0), (x1, y1) = lane.getShape()[-1], to_lane.getShape()[0]
    return float(math.hypot(x1 - x0, y1 - y0))


class RouteTable:
    """Routes inside regions as steps (module docstring), added on first use."""

    def __init__(self, arrays: RegionArrays):
        self.arrays = arrays
        self.first: dict[tuple, int] = {}  # (region, edges) -> its first step
        n = 64
        self.lanes = np.full((n, MAX_CANDIDATES), -1, np.int64)
        self.link = np.full((n, MAX_CANDIDATES), -1, np.int64)
        self.junction = np.zeros((n, MAX_CANDIDATES), np.float64)
        self.turn = np.full((n, MAX_CANDIDATES), np.inf, np.float64)  # the link's speed across the junction
        self.targets = np.full((n, MAX_CANDIDATES, MAX_TARGETS), -1, np.int64)  # lanes the links lead to
        self.way = np.full((n, MAX_CANDIDATES), -1, np.int64)  # the link's index (:class:`Link`)
        self.next = np.full(n, -1, np.int64)
        self.leave = np.full(n, np.inf, np.float64)
        self.size = 0

    def step_of(self, region: int, edges) -> int:
        """The first step of the route ``edges`` in region ``region`` (added if new)."""
        key = (region, tuple(edges))
        if key not in self.first:
            self.first[key] = self._add(region, key[1])
        return self.first[key]

    def _grow(self, need: int) -> None:
        if need <= len(self.next):
            return
        n = max(need, 2 * len(self.next))
        for name, fill in (("lanes", -1), ("link", -1), ("junction", 0.0), ("turn", np.inf), ("targets", -1), ("way", -1), ("next", -1), ("leave", np.inf)):
            old = getattr(self, name)
            new = np.full((n, *old.shape[1:]), fill, old.dtype)
            new[:len(old)] = old
            setattr(self, name, new)

    def _add(self, region: int, edges: tuple) -> int:
        a = self.arrays
        known = [e for e in edges if e in a.edge_lanes[region]]
        if not known:
            raise BadInput(f"a route with no edge in the region of {a.lights[region]}: {list(edges)[:3]}")
        edges = tuple(known)
        first = self.size
        self._grow(first + len(edges))
        links, exits = a.links[region], dict(a.regions[region].exits)
        for k, e in enumerate(edges):
            s, lanes = first + k, a.edge_lanes[region][e]
            nxt = edges[k + 1] if k + 1 < len(edges) else None
            ok = [(x, links[(_local(a, x), nxt)]) for x in lanes if nxt and (_local(a, x), nxt) in links]
            if not ok:  # its last edge here, or no lane goes on: it leaves at the exit or the edge's end
                ok = [(x, Link(-1, 0.0, [], -1, None)) for x in lanes]
                self.leave[s] = exits.get(e, a.lane_length[lanes[0]])
                nxt = None
            for j, (x, link) in enumerate(ok[:MAX_CANDIDATES]):
                self.lanes[s, j], self.link[s, j], self.junction[s, j] = x, link.code, link.metres
                self.turn[s, j] = link.speed
                self.way[s, j] = link.index
                self.targets[s, j, :len(link.targets[:MAX_TARGETS])] = link.targets[:MAX_TARGETS]
            self.next[s] = s + 1 if nxt else -1
            if nxt is None:
                self.size = s + 1
                return first
        self.size = first + len(edges)
        return first


def _local(arrays: RegionArrays, lane: int) -> str:
    """The network's id of lane ``lane``."""
    return arrays.lane_ids[lane].split("__", 1)[1]


__all__ = ["GREEN", "KIND_DEFAULTS", "Link", "MINOR", "RED", "RegionArrays", "RouteTable", "SignalRows", "YELLOW", "signal_rows",
           "vehicle_kinds"]
