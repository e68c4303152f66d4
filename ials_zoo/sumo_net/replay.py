"""Every light's region replayed: the local simulators of a network fed the GS's own influence.

The contract a local simulator must keep (before any AIP predicts its influence): given the
vehicles that entered its region in the GS, where and as they entered, it reproduces the
region's lanes. :class:`ReplayCore` runs both halves in the process that owns the simulation
(a :class:`~ials_zoo.sumo.lease.SimHandle` core, so the lease rules hold):

1. :meth:`ReplayCore.record`: the GS (the network's own programs, its routes) for ``seconds``;
   each step, every vehicle that appears on a region's edges, from outside it or inserted there,
   is recorded with its lane, position, speed, type, speed factor and the rest of its route
   inside the region (once, also while it crosses a junction inside the region), and the watched
   lanes are read (vehicles, halting vehicles).
2. :meth:`ReplayCore.replay`: every region cut from the network (:func:`cut_regions`, ids prefixed
   by the light) side by side in one simulation, the lights on the same programs from the same
   second; each recorded vehicle is inserted where the GS had it, with the GS's speed factor,
   at the highest safe speed (inserted at the GS's speed, SUMO held back a sixth of them for
   seconds until that speed was safe: 6 waiting at every step on ingolstadt21, and the replay
   cost 3x more), and the same lanes are read.

:func:`replay_error` compares the two: per lane and step, the mean absolute difference of
vehicles and of halting vehicles, over the GS's mean.
"""

from __future__ import annotations

import functools
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.sumo.command import close_any_simulation, load_budget, start_simulation, sumo_command
from ials_zoo.sumo.lease import SimHandle, import_libsumo
from ials_zoo.sumo_net.arrays import ArraySim
from ials_zoo.sumo_net.arrays_layout import RegionArrays, vehicle_kinds
from ials_zoo.sumo_net.core import _Signal
from ials_zoo.sumo_net.mdp import wait_norm
from ials_zoo.sumo_net.metrics import MAX_ROUTE_BYTES, iter_elements
from ials_zoo.sumo_net.network import read_network
from ials_zoo.sumo_net.regions import cut_network, netconvert, region_prefix

MAX_DISTANCE = 200.0  # RESCO's detection (m), as the env's default


def vehicle_types(route_files, out: Path) -> Path:
    """The route files' vehicle types as an additional file (cut networks carry none)."""
    root = ET.Element("additional")
    for f in route_files:
        for el in iter_elements(f, MAX_ROUTE_BYTES, "vType"):
            root.append(el)
    ET.ElementTree(root).write(out)
    return out


def cut_regions(net_file: str, regions: dict, folder: Path, timeout: float = 600.0) -> Path:
    """Every region cut from ``net_file`` (ids prefixed :func:`~ials_zoo.sumo_net.regions.region_prefix`) and merged into one
    network in ``folder``; returns its path."""
    folder = Path(folder)
    cuts = [str(cut_network(net_file, r, folder / f"region_{i}.net.xml", prefix=region_prefix(light)))
            for i, (light, r) in enumerate(regions.items())]
    merged = folder / "regions.net.xml"
    netconvert(["--sumo-net-file", ",".join(cuts), "--output-file", str(merged)], "merging the regions", timeout)
    return merged


def replay_error(gs_states, local_states) -> dict[str, float]:
    """Mean absolute difference per lane and step over the GS's mean, of vehicles and halting."""
    gs, local = np.asarray(gs_states, float), np.asarray(local_states, float)
    error = np.abs(gs - local).mean(axis=(0, 1))
    scale = np.maximum(gs.mean(axis=(0, 1)), 1e-9)
    return {"vehicles": float(error[0] / scale[0]), "halting": float(error[1] / scale[1])}


def measures_error(gs_measures, local_measures) -> dict[str, float]:
    """The lights' RESCO observation (per lane: approach, total wait, queue, speed sum) and
    reward (``wait_norm``) in both runs, at every decision: the mean absolute difference over the
    GS's mean absolute value, per quantity (the observation's over its lanes and decisions)."""

    out = {}
    gs = np.concatenate([np.concatenate(m) for m in gs_measures])  # [decisions * lanes, 5]
    local = np.concatenate([np.concatenate(m) for m in local_measures])
    for k, name in enumerate(("approach", "total_wait", "queue", "speed_sum")):
        out[name] = float(np.abs(gs[:, k] - local[:, k]).mean() / max(np.abs(gs[:, k]).mean(), 1e-9))
    r_gs = np.array([[wait_norm(x, 0) for x in m] for m in gs_measures])
    r_local = np.array([[wait_norm(x, 0) for x in m] for m in local_measures])
    out["reward"] = float(np.abs(r_gs - r_local).mean() / max(np.abs(r_gs).mean(), 1e-9))
    return out


def contract_errors(error: dict) -> dict[str, float]:
    """The replay contract's four figures from :func:`replay_regions`' ``error``: lanes'
    vehicles and halting, the observation's worst quantity, the reward."""
    observation = max(error["approach"], error["total_wait"], error["queue"], error["speed_sum"])
    return {"vehicles": error["vehicles"], "halting": error["halting"], "observation": observation,
            "reward": error["reward"]}


def _inside(route, index: int, edges: set) -> tuple:
    out = []
    for e in route[max(index, 0):]:
        if e not in edges:
            break
        out.append(e)
    return tuple(out)


class ReplayCore:
    """Runs :meth:`record` (the GS) and :meth:`replay` (the local simulators), one at a time."""

    LOADS = ("record", "plain", "replay")  # the methods that start SUMO (SimHandle's loads)

    def __init__(self):
        self.ls = import_libsumo()
        self.running = False
        self.seconds_spent = 0.0  # in SUMO's steps (and insertions) of the last run

    def _lanes(self, lanes) -> list:
        lane = self.ls.lane
        return [(lane.getLastStepVehicleNumber(x), lane.getLastStepHaltingNumber(x)) for x in lanes]

    def _run(self, command: list[str], begin: int, seconds: int) -> None:
        close_any_simulation(self)
        start_simulation(self.ls, command + ["--begin", str(begin), "--end", str(begin + seconds), "--time-to-teleport", "-1"])
        self.running = True

    def plain(self, net_file, route_files, begin: int, seconds: int, seed: int = 0) -> float:
        """The GS's ``seconds`` with nothing recorded: seconds per step (its cost alone)."""
        self._run(sumo_command(seed, net=net_file, routes=list(route_files)), begin, seconds)
        step, start = self.ls._libsumo.simulation_step, time.perf_counter()
        try:
            for _ in range(seconds):
                step(0.0)
            return (time.perf_counter() - start) / seconds
        finally:
            close_any_simulation(self)

    def _observer(self, signals, every: int):
        """A function of the step index that returns every light's RESCO measures (``[lanes, 5]``,
        :class:`ials_zoo.sumo_net.core._Signal`) every ``every`` steps, else None."""

        watched = [_Signal(lanes, lengths) for lanes, lengths in signals]
        raw = self.ls._libsumo

        def observe(k: int):
            if (k + 1) % every:
                return None
            return [w.observe(raw, every, MAX_DISTANCE) for w in watched]

        return observe

    def record(self, net_file, route_files, begin: int, seconds: int, region_edges: dict, lanes, signals,
               every: int, seed: int = 0, entry_offsets: dict | None = None):
        """The GS's ``seconds`` from ``begin``: ``(entries per step, lane states per step, the
        lights' measures every ``every`` steps)``; an entry is ``(light, vehicle, edges inside,
        lane index, position, speed, type, speed factor)``; ``signals``: every light's ``(lanes,
        lane lengths)``; ``entry_offsets``: per light, ``{edge: metres}`` of its entry edges
        whose first metres are outside the region."""
        ls, v = self.ls, self.ls.vehicle
        self._run(sumo_command(seed, net=net_file, routes=list(route_files)), begin, seconds)
        observe = self._observer(signals, every)
        edges_of = {light: set(edges) for light, edges in region_edges.items()}
        offsets = {light: (entry_offsets or {}).get(light, {}) for light in edges_of}
        present = {light: set() for light in edges_of}
        entries, states, measures, self.seconds_spent = [], [], [], 0.0
        try:
            for k in range(seconds):
                t0 = time.perf_counter()
                ls.simulationStep()
                self.seconds_spent += time.perf_counter() - t0
                alive, step = set(v.getIDList()), []
                for light, edges in edges_of.items():
                    now = {x for e in edges for x in ls.edge.getLastStepVehicleIDs(e)
                           if e not in offsets[light] or v.getLanePosition(x) >= offsets[light][e]}
                    # a vehicle crossing a junction inside the region is on none of its edges
                    known = {x for x in present[light] if x in alive and (x in now or v.getRoadID(x).startswith(":"))}
                    for x in sorted(now - known):
                        inside = _inside(v.getRoute(x), v.getRouteIndex(x), edges)
                        if inside:
                            step.append((light, x, inside, v.getLaneIndex(x), v.getLanePosition(x), v.getSpeed(x),
                                         v.getTypeID(x), v.getSpeedFactor(x)))
                    present[light] = known | now
                entries.append(step)
                states.append(self._lanes(lanes))
                measures.append(observe(k))
        finally:
            close_any_simulation(self)
        return entries, states, [m for m in measures if m is not None]

    def replay(self, merged_net, additionals, begin: int, entries, lanes, signals, every: int, seed: int = 0):
        """The local simulators fed ``entries`` (of :meth:`record`): lane states per step and the
        lights' measures every ``every`` steps (lanes named with their light's prefix)."""
        ls = self.ls
        self._run(sumo_command(seed, net=str(merged_net), additionals=[str(a) for a in additionals]), begin,
                  len(entries))
        observe = self._observer(signals, every)
        states, measures, n, self.seconds_spent = [], [], 0, 0.0
        try:
            for k, step in enumerate(entries):
                t0 = time.perf_counter()
                for light, x, edges, lane, pos, _speed, vtype, factor in step:
                    n += 1
                    ls.route.add(f"r{n}", [region_prefix(light) + e for e in edges])
                    vid = f"{region_prefix(light)}{x}__{n}"
                    ls.vehicle.add(vid, f"r{n}", typeID=vtype, depart="now", departLane=str(lane),
                                   departPos=str(max(pos, 0.0)), departSpeed="max")
                    ls.vehicle.setSpeedFactor(vid, factor)
                ls.simulationStep()
                self.seconds_spent += time.perf_counter() - t0
                states.append(self._lanes(lanes))
                measures.append(observe(k))
        finally:
            close_any_simulation(self)
        return states, [m for m in measures if m is not None]

    def timing(self) -> float:
        return self.seconds_spent

    def close(self) -> None:
        close_any_simulation(self)


def replay_each(sim, scenario, regions: dict, entries, folder, seed: int = 0) -> dict[str, float]:
    """Every region alone in a simulation of its own, fed its entries: seconds per step, by light
    (what a single learner's local simulator costs)."""
    out = {}
    for k, (light, region) in enumerate(regions.items()):
        alone = Path(folder) / f"alone_{k}"
        alone.mkdir(parents=True, exist_ok=True)
        merged = cut_regions(scenario.net_file, {light: region}, alone)
        mine = [[e for e in step if e[0] == light] for step in entries]
        sim.call("replay", merged, [Path(folder) / "vtypes.add.xml"], scenario.begin, mine, [], [], len(mine) + 1,
                 seed)
        out[light] = sim.call("timing") / max(len(mine), 1)
    return out


def replay_arrays(scenario, regions: dict, entries, observed: list, seed: int = 0, shares: dict | None = None) -> tuple:
    """The array local simulator (:mod:`ials_zoo.sumo_net.arrays`) of ``regions`` (in the
    order of ``observed``: per region, its light's lanes), every light on its own program, fed
    ``entries`` (of :meth:`ReplayCore.record`): ``(lane states per step, the lights' measures
    every decision, seconds per step)``; ``shares``: its lane calibration
    (:func:`~ials_zoo.sumo_net.arrays_calibration.lane_shares`), none if None."""
    arrays = RegionArrays(scenario.net_file, regions, scenario.yellow_seconds, driven=False, begin=scenario.begin)
    arrays.calibrate(shares or {})
    sim = ArraySim(arrays, vehicle_kinds(scenario.route_files), 1, observed, seed, patience=None)
    index = {light: r for r, light in enumerate(regions)}
    every, states, measures = scenario.decision_seconds, [], []
    splits = np.cumsum([len(x) for x in observed])[:-1]  # the rows of each light
    start = time.perf_counter()
    for k, step in enumerate(entries):
        for light, _x, edges, lane, pos, _speed, vtype, factor in step:
            if light in index:
                sim.enter(0, index[light], edges, lane, max(pos, 0.0), vtype, factor)
        sim.advance()
        states.append(sim.lane_states())
        if (k + 1) % every == 0:
            measures.append(np.split(sim.measures(every, MAX_DISTANCE), splits))
    return states, measures, (time.perf_counter() - start) / max(len(entries), 1)


def replay_regions(scenario, regions: dict, seconds: int, folder, seed: int = 0, measure_cost: bool = False,
                   noise_floor: bool = False, each: bool = False, local: str = "sumo",
                   calibration: dict | None = None) -> dict:
    """Record the GS's ``seconds`` and replay ``regions`` (light -> :class:`NetRegion`) fed with
    it; ``folder`` takes the cut networks. Returns ``error`` (:func:`replay_error` over the
    regions' controlled lanes), ``inserted`` (vehicles), ``local_seconds_per_step``, the lanes
    and both runs' lane states; ``measure_cost``: also ``gs_seconds_per_step`` (the GS alone);
    ``noise_floor``: also the error between two replays of seeds ``seed`` and ``seed + 1``
    (the local simulator's own randomness, given the same entries); ``each``: also every region
    alone (:func:`replay_each`, ``each_seconds_per_step``; SUMO only); ``local``: the local
    simulator, ``"sumo"`` (the regions cut from the network) or ``"arrays"``
    (:func:`replay_arrays`, with the lane shares ``calibration``)."""
    if local not in ("sumo", "arrays"):
        raise BadInput(f"local: expected 'sumo' or 'arrays', got {local!r}")
    lights = [x for x in read_network(scenario.net_file).lights if x.id in regions]
    gs_lanes = [lane for x in lights for lane in x.lanes]
    gs_signals = [(x.lanes, x.lane_lengths) for x in lights]
    sim = SimHandle("ials_zoo.sumo_net.replay:ReplayCore", {}, "auto", timeout=3600.0, loads=ReplayCore.LOADS,
                    load_seconds=load_budget(scenario.net_file, *scenario.route_files))
    out = {"lanes": gs_lanes}
    try:
        if measure_cost:
            out["gs_seconds_per_step"] = sim.call("plain", scenario.net_file, scenario.route_files, scenario.begin,
                                                  seconds, seed)
        edges = {light: r.edges for light, r in regions.items()}
        entries, out["gs"], gs_measures = sim.call("record", scenario.net_file, scenario.route_files,
                                                   scenario.begin, seconds, edges, gs_lanes, gs_signals,
                                                   scenario.decision_seconds, seed)
        if local == "arrays":
            ordered = {x.id: regions[x.id] for x in lights}
            replay = functools.partial(replay_arrays, scenario, ordered, entries, [x.lanes for x in lights],
                                       shares=calibration)
        else:
            replay = _sumo_replay(sim, scenario, regions, lights, entries, Path(folder))
        out["local"], local_measures, out["local_seconds_per_step"] = replay(seed)
        out["error"], out["inserted"] = replay_error(out["gs"], out["local"]), sum(map(len, entries))
        out["error"].update(measures_error(gs_measures, local_measures))
        if noise_floor:
            again, again_measures, _ = replay(seed + 1)
            out["noise_floor"] = replay_error(out["local"], again)
            out["noise_floor"].update(measures_error(local_measures, again_measures))
        if each and local == "sumo":
            out["each_seconds_per_step"] = replay_each(sim, scenario, regions, entries, folder, seed)
    finally:
        sim.close()
    return out


def _sumo_replay(sim, scenario, regions: dict, lights: list, entries, folder: Path):
    """The SUMO regions' replay of ``entries`` as a function of the seed (:func:`replay_arrays`'s result)."""
    merged = cut_regions(scenario.net_file, regions, folder)
    vtypes = vehicle_types(scenario.route_files, folder / "vtypes.add.xml")
    local_lanes = [region_prefix(x.id) + lane for x in lights for lane in x.lanes]
    local_signals = [([region_prefix(x.id) + lane for lane in x.lanes], x.lane_lengths) for x in lights]

    def replay(seed: int):
        states, measures = sim.call("replay", merged, [vtypes], scenario.begin, entries, local_lanes, local_signals,
                                    scenario.decision_seconds, seed)
        return states, measures, sim.call("timing") / max(len(entries), 1)

    return replay


__all__ = ["MAX_DISTANCE", "ReplayCore", "contract_errors", "cut_regions", "measures_error", "replay_arrays", "replay_each", "replay_error", "replay_regions",
           "vehicle_types"]
