"""The IALS's core on arrays: :class:`~ials_zoo.sumo_net.island.IslandCore`'s contract (RESCO's
signal loop fed influence sources, with the region data) on the array local simulator
(:mod:`ials_zoo.sumo_net.arrays`) instead of SUMO regions.

Rows are ``(copy, light)``, copy-major: every light's region once per copy. Each decision it
takes per row an action and the influence sources (:mod:`ials_zoo.sumo_net.influence`): per
entry point and second how many vehicles come in, each drawn from the GS's entries there
(:func:`~ials_zoo.sumo_net.island.entry_tables`), as the island
draws them (one stream for every row: the batch draws them at once); per exit whether it is blocked (its lanes held at
:data:`~ials_zoo.sumo_net.island.BLOCKED_SPEED`; blocked :data:`~ials_zoo.sumo_net.island.GRIDLOCK_DECISIONS`
decisions in a row, it stays blocked). It returns RESCO's measures, the lights' phases, the time
and ``(influences, d-sets)``, the d-sets read from the arrays as the
:class:`~ials_zoo.sumo_net.influence.EntryWatcher` reads them from SUMO.

Holds no SUMO simulation: it runs in the caller's process (:class:`ials_zoo.sumo.lease.PlainHandle`).
"""

from __future__ import annotations

import os

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.sumo_net.arrays import FIELDS, ArraySim
from ials_zoo.sumo_net.arrays_layout import RegionArrays, vehicle_kinds
from ials_zoo.sumo_net.influence import CELL_METRES, CELLS, HALTING_SPEED, HELD_DECISIONS, region_layout
from ials_zoo.sumo_net.island import BLOCKED_SPEED, GRIDLOCK_DECISIONS, INSERT_PATIENCE
from ials_zoo.sumo_net.regions import regions_of

PACKED_METRES = 7.5  # a jammed lane's metres per vehicle (SUMO's default length and gap)
WORKING_COPIES = 6  # the per-second arrays (sorting, speeds, positions) alongside the pool
ENTRY_STREAM = 1  # the entries' draws: a stream of the episode's seed apart from the simulator's


class ArrayNetCore:
    """The core (module docstring). Config: ``net_file``, ``route_files``, ``begin``, ``decision``,
    ``yellow``, ``lights`` (every region's light, in row order), ``lanes`` (their incoming lanes),
    ``controlled`` (the lights actions drive, per copy in this order; the others run their own
    program), ``max_distance``, ``tables`` (per light, per entry point: the GS's entries),
    ``copies``, ``lane_shares`` (the lane calibration, :mod:`ials_zoo.sumo_net.arrays_calibration`)."""

    def __init__(self, net_file, route_files, begin, decision, yellow, lights, lanes, tables, controlled=None,
                 copies=1, max_distance=200.0, lane_shares=None, **_ignored):
        self.begin, self.decision, self.yellow = int(begin), int(decision), int(yellow)
        self.lights, self.copies = list(lights), int(copies)
        self.max_distance = float(max_distance)
        regions = regions_of(net_file)
        self.controlled = list(self.lights if controlled is None else controlled)
        self.arrays = RegionArrays(net_file, {x: regions[x] for x in self.lights}, self.yellow, driven=self.controlled,
                                   begin=self.begin)
        self.arrays.calibrate(lane_shares or {})
        check_memory(self.arrays, self.copies)
        self.sim = ArraySim(self.arrays, vehicle_kinds(route_files), self.copies, [list(x) for x in lanes],
                            patience=INSERT_PATIENCE)
        self.tables = list(tables) if isinstance(tables, list) else [tables[x] for x in self.lights]
        names = self.arrays.signals.names
        self.own_row = np.array([names.index((r, x)) for r, x in enumerate(self.lights)], np.int64)
        self.driven_row = self.own_row[[self.lights.index(x) for x in self.controlled]]
        self._yellows()
        self.data = RegionData(self.arrays, [region_layout(net_file, x) for x in self.lights], self.decision,
                               self.copies)
        self.held = np.zeros((self.copies, self.data.n_exits), np.int64)
        # the contract's row k = copy * lights + light is the region-major row q = light * copies + copy
        n, c = len(self.lights), self.copies
        self.row_order = [r * c + j for j in range(c) for r in range(n)]  # contract row k -> q
        self.contract_row = [(q % c) * n + q // c for q in range(n * c)]  # q -> contract row k
        self.as_blocks = False  # step_blocks' callers read the d-sets as blocks
        self.time, self.rng, self.queues = self.begin, None, []
        self._entry_tables()

    # -- the episode -----------------------------------------------------------------------------
    def reset(self, seed: int, tripinfo=None):
        """A new episode: no vehicles, every light at its first green, the entries' random
        stream from ``seed``."""
        self.sim.reset(seed)
        self.rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(ENTRY_STREAM,)))
        self.held[:] = 0
        self.time, self.queues = self.begin, []
        self.plan = np.zeros(self.data.plan_start[-1], np.int64)
        return self._observe()

    def step(self, actions, influences):
        """One decision: the actions (green indices) of the controlled lights, copy-major, and
        every row's influence sources (rows ``copy * lights + light``)."""
        return self._step(actions, np.concatenate([np.asarray(influences[k], np.int64) for k in self.contract_row]))

    def step_blocks(self, actions, blocks) -> tuple:
        """:meth:`step` with each region's sources as one block ``[copies, its sources]``;
        returns the measures, phases and time (the d-sets: :meth:`dset_blocks`)."""
        return self._step(actions, np.concatenate([np.asarray(b, np.int64).reshape(-1) for b in blocks]))

    def _step(self, actions, plan: np.ndarray):
        d = self.data
        self.plan = plan
        if len(self.plan) != d.plan_start[-1]:
            raise ValueError(f"influences: {len(self.plan)} sources in all, expected {d.plan_start[-1]}")
        blocked = (self.plan[d.exit_pos] > 0) | (self.held >= GRIDLOCK_DECISIONS)
        self.plan[d.exit_pos] = blocked  # a gridlock is what the sources say too
        lanes = d.exit_lane[None, :] + np.arange(self.copies)[:, None] * self.arrays.n_lanes
        self.sim.limit[lanes] = np.where(blocked[:, d.exit_of_pair], BLOCKED_SPEED,
                                         self.arrays.lane_speed[d.exit_lane][None, :])
        due = self._entries_due()
        rows, copies, greens = self._show_yellows(actions)
        self._advance(0, self.yellow, due)
        self.sim.phase[copies, rows] = greens  # every driven light to its action, its timer restarted
        self.sim.elapsed[copies, rows] = -1.0
        self._advance(self.yellow, self.decision, due)
        self.held = np.where(blocked, self.held + 1, 0)
        return self._observe()

    def _show_yellows(self, actions) -> tuple:
        """RESCO's switch (:meth:`ials_zoo.sumo_net.core.NetCore.step`), its first half: a light
        whose action is another green shows the yellow between them. Returns the driven lights'
        ``(signal rows, copies, actions)``, ``[copies, driven]`` each: the greens set after the
        yellow seconds."""
        a = np.asarray(actions, np.int64).reshape(self.copies, len(self.controlled))
        rows = np.broadcast_to(self.driven_row, a.shape)
        copies = np.broadcast_to(np.arange(self.copies)[:, None], a.shape)
        current = self.sim.phase[copies, rows]
        yellow = self.yellow_table[np.arange(len(self.controlled))[None, :], np.minimum(current, self._width - 1), a]
        switch = (current != a) & (current < self._width) & (yellow >= 0)
        self.sim.phase[copies[switch], rows[switch]] = yellow[switch]
        self.sim.elapsed[copies[switch], rows[switch]] = -1.0
        return rows, copies, a

    def _yellows(self) -> None:
        """``[driven light, from green, to green]``: RESCO's yellow phase between the two, -1 if none."""
        signals = self.arrays.signals
        self._width = int(max(signals.phase_start[row + 1] - signals.phase_start[row] for row in self.driven_row))
        self.yellow_table = np.full((len(self.driven_row), self._width, self._width), -1, np.int64)
        for i, row in enumerate(self.driven_row):
            for (x, y), phase in signals.yellow_of[row].items():
                self.yellow_table[i, x, y] = phase

    def _entry_tables(self) -> None:
        """Every region's entry tables as rows of the simulator's pending entries, one array:
        table ``(region, point)`` is rows ``table_start[t]`` to ``table_start[t] + table_size[t]``."""
        rows, starts, sizes = [], [], []
        for r, tables in enumerate(self.tables):
            for table in tables:
                starts.append(len(rows))
                sizes.append(len(table))
                rows += [self.sim.entry_row(r, edges, lane, max(pos, 0.0), vtype, factor)
                         for edges, lane, pos, vtype, factor in table]
        self.entry_rows = np.array(rows, np.float64).reshape(-1, 6)
        self.table_start, self.table_size = np.array(starts, np.int64), np.array(sizes, np.int64)
        self.point_base = np.concatenate([[0], np.cumsum([len(t) for t in self.tables])])

    def _entries_due(self) -> list[np.ndarray]:
        """Per second of this decision, the entries the sources name, each drawn from its entry
        point's table (the rows' stream), as the simulator's pending rows."""
        d = self.data
        counts = self.plan[d.entry_pos]
        nz = np.flatnonzero(counts)
        which = np.repeat(nz, counts[nz])
        row = d.entry_row[which]
        table = self.point_base[row // self.copies] + d.entry_point[which]
        size = self.table_size[table]
        keep = size > 0
        which, row, table, size = which[keep], row[keep], table[keep], size[keep]
        drawn = self.entry_rows[self.table_start[table] + (self.rng.random(len(table)) * size).astype(np.int64)]
        drawn[:, 0] += (row % self.copies) * self.arrays.n_lanes
        second = d.entry_second[which]
        return [drawn[second == s] for s in range(self.decision)]

    def _advance(self, start: int, stop: int, due: list) -> None:
        for second in range(start, stop):
            if len(due[second]):
                self.sim.enter_rows(due[second])
            self.sim.advance()
            self.time += 1

    # -- what the lights and the AIPs see ------------------------------------------------------------
    def _observe(self):
        measures = self.sim.measures(self.decision, self.max_distance)
        self.queues.append(float(measures[:, 2].sum()) / (self.copies * len(self.lights)))
        phases = self.sim.phase[:, self.own_row].reshape(-1)
        self.flat_dsets = self._dsets()
        if self.as_blocks:
            return measures, phases, float(self.time)
        d, order = self.data, self.row_order
        told = [self.plan[d.plan_start[q]:d.plan_start[q + 1]] for q in order]
        dsets = [self.flat_dsets[d.dset_start[q]:d.dset_start[q + 1]] for q in order]
        return measures, phases, float(self.time), (told, dsets)

    def dset_blocks(self) -> list[np.ndarray]:
        """The last d-sets as one block per region, ``[copies, its d-set]``."""
        s, c = self.data.dset_start, self.copies
        return [self.flat_dsets[s[r * c]:s[(r + 1) * c]].reshape(c, -1) for r in range(len(self.lights))]

    def _dsets(self) -> list[np.ndarray]:
        """Per row: the occupancy cells of its entry lanes, its exits blocked now (a vehicle
        halting before where it would leave, or its source says so) and how long each lasted."""
        d, v, n = self.data, self.sim.v, self.arrays.n_lanes
        flat = np.zeros(d.dset_start[-1], np.uint8)
        alive = np.flatnonzero(v.alive)
        copy, lane, pos = v.lane[alive] // n, v.lane[alive] % n, v.pos[alive]
        cell = ((pos - d.cell_offset[lane]) // CELL_METRES).astype(np.int64)
        on = (d.cell_base[lane] >= 0) & (cell >= 0) & (cell < CELLS)
        flat[d.dset_start[:-1][d.region_of_lane[lane[on]] * self.copies + copy[on]] + d.cell_base[lane[on]]
             + cell[on]] = 1
        exit_ = d.exit_of_lane[lane]
        halted = (exit_ >= 0) & (v.speed[alive] < HALTING_SPEED) & (pos <= d.exit_leave[np.maximum(exit_, 0)])
        now = self.plan[d.exit_pos] > 0
        now[copy[halted], exit_[halted]] = True
        flat[d.now_pos] = now
        flat[d.held_pos] = self.held[:, :, None] >= np.asarray(HELD_DECISIONS)
        return flat

    # -- the core's other calls -------------------------------------------------------------------------
    def finish(self) -> dict:
        """The episode's mean queue per light (as :meth:`ials_zoo.sumo_net.core.NetCore.finish`)."""
        return {"queue": float(np.mean(self.queues[1:])) if len(self.queues) > 1 else 0.0}

    def timing(self) -> float:
        return 0.0

    def close(self) -> None:
        pass


def memory_bound(arrays: RegionArrays, copies: int) -> int:
    """Bytes the copies could need at most: every lane packed with vehicles (one per
    :data:`PACKED_METRES`), each vehicle's fields and a few arrays of the same size per second."""
    vehicles = copies * float(np.sum(np.maximum(arrays.lane_length, PACKED_METRES) // PACKED_METRES))
    return int(vehicles * len(FIELDS) * 8 * WORKING_COPIES + copies * arrays.n_lanes * 8 * 8)


def check_memory(arrays: RegionArrays, copies: int) -> None:
    """A clear error, before any work, where the copies could outgrow half this machine's memory."""
    need = memory_bound(arrays, copies)
    try:
        have = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return  # no way to know here: the pool grows as it needs
    if need > have // 2:
        raise BadInput(f"{copies} copies of {len(arrays.lights)} regions ({arrays.n_lanes:,} lanes each) could need "
                       f"{need / 2**30:.1f} GiB with every lane jammed, more than half of this machine's "
                       f"{have / 2**30:.1f} GiB: use fewer copies")


class RegionData:
    """Where each row's influence sources and d-set bits lie in flat arrays over every row, so
    that one numpy pass reads or writes them all. Inside, rows are region-major (``region *
    copies + copy``): a region's rows of every copy are one block ``[copies, its sources]``,
    what its AIP reads and draws for all copies at once."""

    def __init__(self, arrays, layouts: list, decision: int, copies: int):
        points = [len(x.points) for x in layouts]
        exits = [len(x.exits) for x in layouts]
        sources = [len(x.source_lanes) for x in layouts]
        rows = [r for r in range(len(layouts)) for _ in range(copies)]
        self.plan_start = np.concatenate([[0], np.cumsum([decision * points[r] + exits[r] for r in rows])])
        dset = [sources[r] * CELLS + exits[r] * (1 + len(HELD_DECISIONS)) for r in rows]
        self.dset_start = np.concatenate([[0], np.cumsum(dset)])
        first_exit = np.concatenate([[0], np.cumsum(exits)])
        self.n_exits = int(first_exit[-1])
        self.region_of_exit = region_of_exit = np.repeat(np.arange(len(layouts)), exits)
        local = np.arange(self.n_exits) - first_exit[region_of_exit]
        c = np.arange(copies)[:, None]
        row = region_of_exit[None, :] * copies + c
        self.exit_pos = self.plan_start[row] + decision * np.asarray(points)[region_of_exit] + local
        base = self.dset_start[row] + np.asarray(sources)[region_of_exit] * CELLS
        self.now_pos = base + local
        self.held_pos = (base + np.asarray(exits)[region_of_exit] + local * len(HELD_DECISIONS))[:, :, None] + \
            np.arange(len(HELD_DECISIONS))
        self.copies = copies
        self._entries(rows, points, decision)
        self._lanes(arrays, layouts, first_exit)

    def _entries(self, rows: list, points: list, decision: int) -> None:
        """Every entry source's row, second and entry point, and its place in the flat plan."""
        k = [np.full(decision * points[r], i) for i, r in enumerate(rows)]
        self.entry_row = np.concatenate(k)
        self.entry_second = np.concatenate([np.repeat(np.arange(decision), points[r]) for r in rows])
        self.entry_point = np.concatenate([np.tile(np.arange(points[r]), decision) for r in rows])
        self.entry_pos = np.concatenate([self.plan_start[i] + np.arange(decision * points[r]) for i, r in enumerate(rows)])

    def _lanes(self, arrays, layouts: list, first_exit) -> None:
        """Per lane of a copy: its region, its first d-set cell within the region's d-set (-1: no
        entry lane) and where its region begins on it, the exit it belongs to (-1: none)."""
        n = arrays.n_lanes
        self.region_of_lane = np.zeros(n, np.int64)
        self.cell_base, self.cell_offset = np.full(n, -1, np.int64), np.zeros(n)
        self.exit_of_lane = np.full(n, -1, np.int64)
        pairs, leave = [], []
        for r, x in enumerate(layouts):
            self.region_of_lane[list(arrays.lane_of[r].values())] = r
            offsets = x.lane_offsets or (0.0,) * len(x.source_lanes)
            for i, (lane, offset) in enumerate(zip(x.source_lanes, offsets)):
                self.cell_base[arrays.lane_of[r][lane]] = i * CELLS
                self.cell_offset[arrays.lane_of[r][lane]] = offset
            for e, (edge, metres) in enumerate(x.exits):
                leave.append(metres)
                for lane in arrays.edge_lanes[r][edge]:
                    self.exit_of_lane[lane] = first_exit[r] + e
                    pairs.append((first_exit[r] + e, lane))
        self.exit_leave = np.array(leave + [0.0])
        pairs = np.array(pairs, np.int64).reshape(-1, 2)
        self.exit_of_pair, self.exit_lane = pairs[:, 0], pairs[:, 1]


__all__ = ["ArrayNetCore", "RegionData", "check_memory", "memory_bound"]
