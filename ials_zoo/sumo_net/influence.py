"""The region data of ``sumo_net_v0``'s junctions: influence sources and d-sets (paper §3).

A light's region is :mod:`ials_zoo.sumo_net.regions`'s (its incoming chains, outgoing edges and
the edges past short exits). What the rest of the network does to it is the vehicles that
come in:

* **influence sources**: per *entry point* and per second of a decision, the vehicles that
  entered the region there during that second, as a class: 0, 1 or 2 (two or more: a third in
  one second on one road is rare). The entry points are the chains'
  first edges (:attr:`~ials_zoo.sumo_net.regions.NetRegion.sources`, in that order; a vehicle
  enters there when it passes the edge's entry offset, 200 m before the stop line), then
  ``"inside"``: vehicles that appear on any other edge of the region from outside it (inserted
  there by the route files, or joining past a short exit). Sources are ordered second-major
  (``"<entry>@<second>"``), so one decision of 10 s has ``10 * (sources + 1)`` of them.
  *Where* an entering vehicle goes inside the region, on which lane and how fast it drives are
  not sources: the local simulator draws them from the GS's own entries at that entry point
  (:mod:`ials_zoo.sumo_net.island`), so the AIP predicts only *when* vehicles come.
  After every second's entries, one source per **exit** and decision (``"exit:<edge>"``, two
  classes): 1 if the region's end of that outgoing road was blocked for at least half of the
  decision's seconds, a vehicle halting (SUMO's < 0.1 m/s) within its first metres (up to where
  vehicles leave the region, :attr:`~ials_zoo.sumo_net.regions.NetRegion.exits`). This is what
  the rest of the network does to the region from downstream: a queue spilling back from the
  next junction. Without it, fed the GS's own entries, the local simulators of ingolstadt21
  under a learned joint policy showed half the GS's waiting, and the policy DIALS trained there
  gridlocked the GS (``docs/sumo_net.md``). One source per decision, not per second: a block
  lasts (on ingolstadt21 under DIALS's policy, 96% of the decisions with a blocked second were
  blocked throughout), and an AIP drawing every second on its own made blocks flicker.
* **d-set** (``"dset"``): the region's local occupancy where vehicles come in, without the
  light's state: per lane of every entry edge, :data:`CELLS` cells of :data:`CELL_METRES` m
  from the entry offset, occupied or not; then per exit, whether it is blocked now; then per
  exit, how long its block has lasted: whether its source said blocked for at least each of
  :data:`HELD_DECISIONS` decisions in a row, up to the last (the GS's measured sources, the
  local simulator's given ones: the same history in both). A jam past an exit that sets in
  lasts: on ingolstadt21 under DIALS's policy, once the cluster's busiest exit was blocked it
  stayed blocked to the episode's end in every episode. An AIP reading only the exit now let a
  block it drew go after a decision or two (``docs/sumo_net.md``, "jams"); reading how long it
  has lasted, it learns from the GS that a long block stays.
* **full** d-set: the d-set and, per incoming lane of the light (its observation's rows),
  whether its detection holds a queue and whether it holds approaching vehicles.

:class:`EntryWatcher` does the bookkeeping every SUMO second in the process that owns the
simulation, the same way in the GS (:class:`RegionNetCore`) and in the local simulator, so
that both measure the same thing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ials_zoo.core.region import RegionSpec
from ials_zoo.sumo_net.core import NetCore
from ials_zoo.sumo_net.names import ENV_ID, SCENARIO_OPTIONS
from ials_zoo.sumo_net.network import read_network
from ials_zoo.sumo_net.regions import edge_lanes, regions_of
from ials_zoo.sumo_net.scenario import scenario_of

ENTRY_CLASSES = 3  # 0, 1, 2 or more vehicles in one second at one entry point
EXIT_CLASSES = 2  # an exit free or blocked
HALTING_SPEED = 0.1  # m/s: SUMO's own threshold of a halting vehicle
INSIDE = "inside"
CELLS, CELL_METRES = 4, 25.0
HELD_DECISIONS = (1, 3, 10)  # a block held this many decisions in a row or more: one d-set bit each


@dataclass(frozen=True)
class RegionLayout:
    """What the bookkeeping needs of one light's region (plain data: it crosses to workers).

    Attributes:
        light: the light's id.
        sources: the entry edges (the chains' first edges), in the region's order.
        edges: every edge of the region.
        source_lanes: every lane of the entry edges, in edge then lane order.
        lanes: the light's incoming lanes (its observation's rows).
        entry_offsets: per entry edge, the lane position (m) where the region begins.
        lane_offsets: the same per source lane.
        exits: ``(edge, position)``: where a vehicle whose way through the region ends on that
            edge leaves it.
    """

    light: str
    sources: tuple[str, ...]
    edges: tuple[str, ...]
    source_lanes: tuple[str, ...]
    lanes: tuple[str, ...]
    entry_offsets: tuple[float, ...] = ()
    lane_offsets: tuple[float, ...] = ()
    exits: tuple[tuple[str, float], ...] = ()

    @property
    def points(self) -> tuple[str, ...]:
        """The entry points: the entry edges, then :data:`INSIDE`."""
        return (*self.sources, INSIDE)

    @property
    def exit_edges(self) -> tuple[str, ...]:
        """The edges where vehicles leave the region (their exit sources' order)."""
        return tuple(e for e, _ in self.exits)

    def prefixed(self, prefix: str) -> RegionLayout:
        """The same region in a simulation whose ids carry ``prefix``."""
        def p(ids):
            return tuple(prefix + x for x in ids)

        return RegionLayout(prefix + self.light, p(self.sources), p(self.edges), p(self.source_lanes), p(self.lanes),
                            self.entry_offsets, self.lane_offsets, tuple((prefix + e, x) for e, x in self.exits))


def region_layout(net_file: str, light: str) -> RegionLayout:
    """The layout of ``light``'s region in the network ``net_file``."""

    region = regions_of(net_file)[light]
    lanes = next(x.lanes for x in read_network(net_file).lights if x.id == light)
    per_source = [edge_lanes(net_file, e) for e in region.sources]
    source_lanes = tuple(lane for x in per_source for lane in x)
    lane_offsets = tuple(offset for x, offset in zip(per_source, region.entry_offsets) for _ in x)
    return RegionLayout(light, region.sources, region.edges, source_lanes, tuple(lanes), region.entry_offsets,
                        lane_offsets, region.exits)


def _scenario(options: dict):
    return scenario_of(**{k: options[k] for k in SCENARIO_OPTIONS if k in options})


def dset_names(layout: RegionLayout) -> dict[str, tuple[str, ...]]:
    cells = tuple(f"occ_{lane}_{k}" for lane in layout.source_lanes for k in range(CELLS))
    cells += tuple(f"blocked_{e}" for e in layout.exit_edges)
    cells += tuple(f"held{n}_{e}" for e in layout.exit_edges for n in HELD_DECISIONS)
    light = tuple(f"{what}_{lane}" for lane in layout.lanes for what in ("queue", "approach"))
    return {"dset": cells, "full": cells + light}


def region_spec(agent: str, **options) -> RegionSpec:
    """The region layout of light ``agent`` under ``sumo_net_v0``'s options, without SUMO."""
    scenario = _scenario(options)
    layout = region_layout(scenario.net_file, agent)
    names = tuple(f"{p}@{s}" for s in range(scenario.decision_seconds) for p in layout.points)
    classes = (ENTRY_CLASSES,) * len(names) + (EXIT_CLASSES,) * len(layout.exits)
    names += tuple(f"exit:{e}" for e in layout.exit_edges)
    params = {"network": scenario.name, "begin": scenario.begin, "end": scenario.end,
              "decision_seconds": scenario.decision_seconds, "yellow_seconds": scenario.yellow_seconds}
    return RegionSpec(domain=ENV_ID, agent=agent, influence_names=names,
                      influence_classes=classes, dset_names=dset_names(layout), params=params)


def full_dset(dset: np.ndarray, measures: np.ndarray) -> np.ndarray:
    """The full d-set from the d-set and the light's measures (``[lanes, 5]``)."""
    light = np.stack([measures[:, 2] > 0, measures[:, 0] > 0], axis=1).reshape(-1)
    return np.concatenate([dset, light.astype(np.uint8)])


class EntryWatcher:
    """Every second, the vehicles entering each watched region, by entry point (module
    docstring); :meth:`dsets` reads the occupancy cells at a decision."""

    def __init__(self, layouts: list[RegionLayout], decision: int):
        self.layouts = list(layouts)
        self.decision = int(decision)
        self.point_of = [{e: j for j, e in enumerate(x.sources)} for x in self.layouts]
        # the entry edges whose first metres are outside the region
        self.offset_of = [{e: o for e, o in zip(x.sources, x.entry_offsets) if o > 0} for x in self.layouts]
        self.counts = [np.zeros((self.decision, len(x.points)), np.int64) for x in self.layouts]
        self.blocked = [np.zeros((self.decision, len(x.exits)), np.int64) for x in self.layouts]
        self.blocked_now = [np.zeros(len(x.exits), np.uint8) for x in self.layouts]
        self.held = [np.zeros(len(x.exits), np.int64) for x in self.layouts]  # decisions each exit's block lasted
        self.present: list[set] = [set() for _ in self.layouts]
        self.second = 0

    def reset(self) -> None:
        self.present = [set() for _ in self.layouts]
        for b in (*self.blocked_now, *self.held):
            b[:] = 0
        self.start_decision()

    def end_decision(self, influences: list) -> None:
        """Count each exit's block on by the decision's sources (per region, as
        :meth:`influences` gives them: its exits last): what the d-set's ``held`` bits read."""
        for held, u, layout in zip(self.held, influences, self.layouts):
            blocked = np.asarray(u[len(u) - len(layout.exits):]) > 0
            held[:] = np.where(blocked, held + 1, 0)

    def start_decision(self) -> None:
        for c in (*self.counts, *self.blocked):
            c[:] = 0
        self.second = 0

    def after_step(self, raw) -> None:
        """Count the vehicles that appeared on each region's edges in the step just taken (a
        vehicle crossing a junction inside the region is on none of its edges, and stays known)."""
        s = min(self.second, self.decision - 1)
        alive = None
        on_edge, position = raw.edge_getLastStepVehicleIDs, raw.vehicle_getLanePosition
        for r, layout in enumerate(self.layouts):
            now, counts, point_of, offset_of = {}, self.counts[r], self.point_of[r], self.offset_of[r]
            for e in layout.edges:
                offset = offset_of.get(e)
                for x in on_edge(e):
                    if offset is None or position(x) >= offset:
                        now[x] = e
            before = self.present[r]
            gone = [x for x in before if x not in now]
            if gone:
                if alive is None:
                    alive = set(raw.vehicle_getIDList())
                kept = {x for x in gone if x in alive and raw.vehicle_getRoadID(x).startswith(":")}
            else:
                kept = set()
            for x, e in now.items():
                if x not in before:
                    counts[s, point_of.get(e, len(point_of))] += 1
            self.present[r] = kept | set(now)
        self.measure_exits(raw)
        for b, now_blocked in zip(self.blocked, self.blocked_now):
            b[s] = now_blocked
        self.second += 1

    def measure_exits(self, raw) -> None:
        """Which exits of every region are blocked now (a vehicle halting in the region's part
        of the road)."""
        for layout, now_blocked in zip(self.layouts, self.blocked_now):
            now_blocked[:] = [_blocked(raw, e, leave) for e, leave in layout.exits]

    def influences(self) -> list[np.ndarray]:
        """Per region, the last decision's sources as classes (int64): every second's entries
        (second-major), then each exit (blocked for at least half the decision)."""
        return [np.concatenate([np.minimum(c, ENTRY_CLASSES - 1).reshape(-1), 2 * b.sum(axis=0) >= self.decision])
                .astype(np.int64) for c, b in zip(self.counts, self.blocked)]

    def dsets(self, raw) -> list[np.ndarray]:
        """Per region, the occupancy cells of its entry lanes, its exits' blocks now and how long
        each has lasted (uint8)."""
        ids, position = raw.lane_getLastStepVehicleIDs, raw.vehicle_getLanePosition
        rows = []
        for layout, blocked, held in zip(self.layouts, self.blocked_now, self.held):
            bits = np.zeros((len(layout.source_lanes), CELLS), np.uint8)
            offsets = layout.lane_offsets or (0.0,) * len(layout.source_lanes)
            for i, (lane, offset) in enumerate(zip(layout.source_lanes, offsets)):
                for x in ids(lane):
                    k = int((position(x) - offset) // CELL_METRES)
                    if 0 <= k < CELLS:
                        bits[i, k] = 1
            lasted = (held[:, None] >= np.asarray(HELD_DECISIONS)).astype(np.uint8).reshape(-1)
            rows.append(np.concatenate([bits.reshape(-1), blocked, lasted]))
        return rows


def _blocked(raw, edge: str, leave: float) -> int:
    """1 if a vehicle halts on ``edge`` before ``leave`` m (where the region ends on it)."""
    if not raw.edge_getLastStepHaltingNumber(edge):
        return 0
    speed, position = raw.vehicle_getSpeed, raw.vehicle_getLanePosition
    return int(any(speed(x) < HALTING_SPEED and position(x) <= leave for x in raw.edge_getLastStepVehicleIDs(edge)))


class RegionNetCore(NetCore):
    """The GS's core (:class:`~ials_zoo.sumo_net.core.NetCore`) that also watches the learners'
    regions: every observation carries ``(influences, dsets)`` (:class:`EntryWatcher`)."""

    def __init__(self, regions: list, **config):
        super().__init__(**config)
        self.watcher = EntryWatcher([RegionLayout(**r) for r in regions], self.decision)

    def reset(self, seed: int, tripinfo: str | None = None):
        self.watcher.reset()
        return super().reset(seed, tripinfo)

    def step(self, actions):
        self.watcher.start_decision()
        return super().step(actions)

    def _advance(self, seconds: int) -> None:
        raw = self.ls._libsumo
        for _ in range(seconds):
            super()._advance(1)
            self.watcher.after_step(raw)

    def _observe(self):
        measures, phases, now = super()._observe()
        raw = self.ls._libsumo
        influences = self.watcher.influences()
        self.watcher.end_decision(influences)
        return measures, phases, now, (influences, self.watcher.dsets(raw))


__all__ = ["CELLS", "CELL_METRES", "ENTRY_CLASSES", "EXIT_CLASSES", "EntryWatcher", "HELD_DECISIONS", "INSIDE", "RegionLayout", "RegionNetCore",
           "full_dset", "region_layout", "region_spec"]
