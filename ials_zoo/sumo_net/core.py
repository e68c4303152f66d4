"""The simulation core of ``sumo_net_v0``: RESCO's signal loop, where libsumo lives.

Runs in the process that owns the simulation (this one under the lease, or a worker; see
:mod:`ials_zoo.sumo.lease`): one call per decision. Read from RESCO's code
(``resco_benchmark/traffic_signal.py`` and ``multi_signal.py``, Pi-Star-Lab/RESCO):

* a controlled light gets a static program of its greens followed by one yellow per ordered
  pair of greens that needs one (``create_yellows``); the actions index the greens;
* one decision: every controlled light whose action differs from its current phase index is
  set to the yellow of (current, action) if there is one; ``yellow`` seconds pass; every
  controlled light is set to its action (``setPhase``: the timer restarts, the net's own phase
  duration applies, so a green shorter than the rest of the interval moves on by itself, as
  in RESCO); the rest of the interval passes; then every light observes;
* observing a light: the vehicles on its incoming lanes whose next light is at most
  ``max_distance`` m ahead; a vehicle's wait starts at SUMO's waiting time when first seen
  stopped and then grows by the decision interval each observation until it leaves the zone
  (RESCO's own bookkeeping); ``queue`` counts those with a wait, ``approach`` the others.

Lights that are not controlled run their own program from the network file.
"""

from __future__ import annotations

import time

import numpy as np

from ials_zoo.sumo.command import close_any_simulation, start_simulation, sumo_command
from ials_zoo.sumo.lease import import_libsumo

# per incoming lane: vehicles approaching, RESCO's total wait (s), queue, sum of speeds (m/s), max wait
MEASURES = ("approach", "total_wait", "queue", "speed_sum", "max_wait")


def yellow_program(greens: list[str], yellow_seconds: int) -> tuple[list[tuple[int, str]], dict]:
    """RESCO's ``create_yellows``: the yellows after the greens, and ``(i, j) -> yellow index``."""
    yellows, index = [], {}
    for i, a in enumerate(greens):
        for j, b in enumerate(greens):
            if i == j:
                continue
            need = [x in "Gg" and y in "rs" for x, y in zip(a, b)]
            if any(need):
                yellows.append((yellow_seconds, "".join("y" if n else x for n, x in zip(need, a))))
                index[(i, j)] = len(greens) + len(yellows) - 1
    return yellows, index


def episode_command(net_file, route_files, begin: int, end: int, seed: int, tripinfo: str | None = None,
                    extra=()) -> list[str]:
    """The SUMO command of one episode: RESCO's (no teleports), its tripinfo as RESCO writes it."""
    options = ["--begin", str(begin), "--end", str(end), "--time-to-teleport", "-1", *extra]
    if tripinfo:
        options += ["--tripinfo-output", tripinfo, "--tripinfo-output.write-unfinished", "true"]
    return sumo_command(seed, net=net_file, routes=route_files, extra=options)


class _Signal:
    """One light's RESCO bookkeeping: its detected vehicles and their waits."""

    def __init__(self, lanes, lengths):
        self.lanes = list(lanes)  # unique (a vehicle is seen once per observation)
        self.lengths = list(lengths)
        self.waits: dict[str, float] = {}  # the vehicles detected last time with a wait

    def observe(self, raw, interval: int, max_distance: float) -> np.ndarray:
        """``raw`` is libsumo's ``_libsumo`` module (its plain functions: no wrapper per call)."""
        rows = []
        last, waits = self.waits, {}  # a vehicle that left the zone is not carried over
        ids, position, waiting, speed = (raw.lane_getLastStepVehicleIDs, raw.vehicle_getLanePosition,
                                         raw.vehicle_getWaitingTime, raw.vehicle_getSpeed)
        for lane, length in zip(self.lanes, self.lengths):
            approach = total = queue = speeds = longest = 0.0
            far = length > max_distance  # a shorter lane is all within detection
            for veh in ids(lane):
                # RESCO reads getNextTLS(veh)[0] distance; on a lane that ends at this light that
                # is the distance to the lane's end, which the lane position gives at a tenth of the cost
                if far and length - position(veh) > max_distance:
                    continue
                wait = last.get(veh)
                wait = wait + interval if wait is not None else waiting(veh)
                if wait > 0:
                    waits[veh] = wait
                    total += wait
                    queue += 1
                    if wait > longest:
                        longest = wait
                else:
                    approach += 1
                speeds += speed(veh)
            rows.append((approach, total, queue, speeds, longest))
        self.waits = waits
        return np.array(rows, np.float64).reshape(len(self.lanes), len(MEASURES))

    def near_counts(self, raw, distance: float) -> list[int]:
        """Per lane, the vehicles whose light is at most ``distance`` m ahead (detected as
        :meth:`observe` detects them): RESCO's MAXWAVE wave at its own detection distance."""
        ids, position = raw.lane_getLastStepVehicleIDs, raw.vehicle_getLanePosition
        out = []
        for lane, length in zip(self.lanes, self.lengths):
            vehicles = ids(lane)
            if length > distance:
                out.append(sum(1 for veh in vehicles if length - position(veh) <= distance))
            else:
                out.append(len(vehicles))
        return out


class NetCore:
    """RESCO's multi-signal loop over one network (see the module docstring).

    Config: ``net_file``, ``route_files``, ``begin``, ``end``, ``decision``, ``yellow``
    (seconds), ``lights`` (every light's id, observed in this order), ``lanes`` (their incoming
    lanes), ``greens`` (their green phases as ``(duration, state)``), ``controlled`` (the ids driven by actions),
    ``max_distance`` (m), ``extra`` (more SUMO options).
    """

    def __init__(self, net_file, route_files, begin, end, decision, yellow, lights, lanes, greens, controlled,
                 max_distance=200.0, extra=()):
        self.ls = import_libsumo()
        self.files = (net_file, tuple(route_files))
        self.begin, self.end = int(begin), int(end)
        self.decision, self.yellow = int(decision), int(yellow)
        self.lights = list(lights)
        self.lanes = [list(x) for x in lanes]
        self.greens = {t: [(float(d), str(s)) for d, s in g] for t, g in zip(self.lights, greens)}
        self.controlled = list(controlled)
        self.max_distance = float(max_distance)
        self.extra = tuple(extra)
        self.running = False
        self.tripinfo = None
        self.signals: list[_Signal] = []
        self._yellow_index: dict[str, dict] = {}
        self._queues: list[float] = []
        self._lengths = None
        self.sim_seconds = 0.0  # wall-clock of SUMO's own start, steps and end (the benchmark's "raw SUMO")

    def _command(self, seed: int, tripinfo: str | None) -> list[str]:
        net, routes = self.files
        return episode_command(net, routes, self.begin, self.end, seed, tripinfo, self.extra)

    def _install(self, tls: str) -> None:
        """Replace the light's program by RESCO's: its greens, then the yellows."""
        tl = self.ls.trafficlight
        greens = self.greens[tls]
        yellows, self._yellow_index[tls] = yellow_program([s for _, s in greens], self.yellow)
        logic = tl.getAllProgramLogics(tls)[0]
        logic.type = 0
        logic.phases = [tl.Phase(d, s) for d, s in greens + yellows]
        tl.setProgramLogic(tls, logic)

    def reset(self, seed: int, tripinfo: str | None = None):
        """Start an episode; returns ``(measures [lanes, 5], phases [lights], time)``."""
        close_any_simulation(self)
        start = time.perf_counter()
        start_simulation(self.ls, self._command(seed, tripinfo))
        self.sim_seconds += time.perf_counter() - start  # loading the network is raw SUMO's work too
        self.running, self.tripinfo = True, tripinfo
        for tls in self.controlled:
            self._install(tls)
        if self._lengths is None:
            self._lengths = [[self.ls.lane.getLength(x) for x in lanes] for lanes in self.lanes]
        self.signals = [_Signal(lanes, lengths) for lanes, lengths in zip(self.lanes, self._lengths)]
        self._queues = []
        return self._observe()

    def _observe(self):
        raw = self.ls._libsumo
        measures = [s.observe(raw, self.decision, self.max_distance) for s in self.signals]
        phase = raw.trafficlight_getPhase
        phases = np.array([phase(t) for t in self.lights], np.int64)
        measures = np.concatenate(measures)
        self._queues.append(float(measures[:, 2].sum()) / len(self.signals))  # the mean of the lights' queues
        return measures, phases, float(raw.simulation_getTime())

    def step(self, actions):
        """One decision of the controlled lights (green indices, in ``controlled`` order)."""
        raw = self.ls._libsumo  # its plain functions: no wrapper per call, no TraCI step listeners
        get_phase, set_phase = raw.trafficlight_getPhase, raw.trafficlight_setPhase
        actions = [int(a) for a in actions]
        for tls, a in zip(self.controlled, actions):
            current = get_phase(tls)
            if current != a and (current, a) in self._yellow_index[tls]:
                set_phase(tls, self._yellow_index[tls][(current, a)])
        self._advance(self.yellow)
        for tls, a in zip(self.controlled, actions):
            set_phase(tls, a)
        self._advance(self.decision - self.yellow)
        return self._observe()

    def _advance(self, seconds: int) -> None:
        """``seconds`` SUMO steps (timed as raw SUMO's work); a local simulator inserts its
        influence here."""
        step = self.ls._libsumo.simulation_step  # the raw call: no TraCI step listeners
        start = time.perf_counter()
        for _ in range(seconds):
            step(0.0)
        self.sim_seconds += time.perf_counter() - start

    def timing(self) -> float:
        """Seconds spent inside SUMO's own start, steps and end since the core was made."""
        return self.sim_seconds

    def near_counts(self, distance: float) -> np.ndarray:
        """Every light's lanes (observation order, concatenated): the vehicles within
        ``distance`` m of the light now (:meth:`_Signal.near_counts`)."""
        raw = self.ls._libsumo
        return np.array([n for s in self.signals for n in s.near_counts(raw, float(distance))], np.float64)

    def make_actuated(self) -> None:
        """Every light on SUMO's actuated control of its own program's phases (type 3)."""
        tl = self.ls.trafficlight
        for tls in self.lights:
            logic = tl.getAllProgramLogics(tls)[0]
            tl.setProgramLogic(tls, tl.Logic("actuated", 3, tl.getPhase(tls), logic.phases))

    def finish(self) -> dict:
        """End the episode (SUMO writes its tripinfo, unfinished trips included, for the caller
        to read: :mod:`ials_zoo.sumo_net.metrics`) and return its mean queue."""
        start = time.perf_counter()
        close_any_simulation(self)
        self.sim_seconds += time.perf_counter() - start  # SUMO's own end: a raw run ends too
        return {"queue": float(np.mean(self._queues[1:])) if len(self._queues) > 1 else 0.0}

    def render_data(self) -> dict:
        """Vehicle positions and every light's signal state, for the viewer."""
        v, tl = self.ls.vehicle, self.ls.trafficlight
        return {"xy": [v.getPosition(x) for x in v.getIDList()],
                "signals": {t: tl.getRedYellowGreenState(t) for t in self.lights}}

    def query(self, domain: str, method: str, *args):
        """A read-only libsumo getter (``domain.method(*args)``), for viewers and tests."""
        if not method.startswith("get"):
            raise ValueError(f"only getters may be queried, not {method!r}")
        return getattr(getattr(self.ls, domain), method)(*args)

    def close(self):
        close_any_simulation(self)


__all__ = ["MEASURES", "NetCore", "episode_command", "yellow_program"]
