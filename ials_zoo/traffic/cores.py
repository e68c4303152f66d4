"""SUMO simulation cores: each method does one whole step's libsumo work and returns arrays.

A core lives where libsumo lives -- this process or a worker process, see
:mod:`ials_zoo.sumo.lease` -- so an env needs exactly one core call per step.

* :class:`GridCore` -- the global grid (the GS);
* :class:`LocalCore` -- ``n`` disjoint copies of one intersection in one network (the LS);
* :class:`_LaneReader` / :class:`_Lights` -- the observation code and the keep/switch light
  control, shared by both cores so that the GS and the LS observe and act alike.
"""

from __future__ import annotations

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.sumo.command import close_any_simulation, start_simulation, sumo_command
from ials_zoo.sumo.lease import import_libsumo
from ials_zoo.traffic.network import CELL_LENGTH, N_CELLS, SPEED_LIMIT

# the grid's routes are fixed: SUMO's rerouting device stays off
_GRID_OPTIONS = ("--device.rerouting.probability", "0")

# ----------------------------------------------------------------------------- shared reading


class _LaneReader:
    """Reads occupancy cells, entries and speeds of groups of 4 incoming lanes.

    Shared by the global and the local core, so both observe with the same code.
    Occupancy: a cell is 1 when the front of a vehicle lies in it; cell ``k`` covers
    ``[k*10, (k+1)*10)`` m upstream of the stop line, cells 0..8 per lane, lanes N, E, S, W.
    Entries: a vehicle is on the lane now and was not at the previous read (the set
    difference of vehicle ids), which also counts vehicles inserted on the lane.
    """

    def __init__(self, lanes: list[list[str]], lengths: list[list[float]]):
        self.groups = lanes
        self.n = len(lanes)
        self.flat = [ln for g in lanes for ln in g]
        self.length = [x for g in lengths for x in g]
        # the raw _libsumo functions skip a Python wrapper layer per call (and are looked up
        # once here, not at every read). Lane mean speed x count equals the sum of the
        # vehicles' speeds (checked against per-vehicle getSpeed in the tests) and saves one
        # call per vehicle.
        L = import_libsumo()._libsumo

        self._getters = (
            L.lane_getLastStepVehicleIDs, L.vehicle_getLanePosition, L.lane_getLastStepMeanSpeed,
        )  # fmt: skip
        # the vehicle ids on each lane at the previous read (tuples, as libsumo returns them)
        self.prev: list[tuple] = [()] * len(self.flat)

    def read(self, with_entries: bool = True):
        """Returns ``(occ [n, 36] uint8, entries [n, 4] uint8, reward [n] float32)``."""
        # this loop is the whole per-step Python cost of the GS and the LS, so it is kept
        # plain (numpy versions and subscriptions measured slower: libsumo's per-object
        # conversions cost the same either way, numpy adds fixed costs)
        get_ids, get_pos, get_mean_speed = self._getters
        n = self.n
        occ = bytearray(n * 4 * N_CELLS)
        entries = bytearray(n * 4)
        reward = [0.0] * n
        prev, lengths, lanes = self.prev, self.length, self.flat
        for g in range(n):
            speed_sum = 0.0
            count = 0
            for a in range(4):
                j = 4 * g + a
                ids = get_ids(lanes[j])
                if ids:
                    base = (4 * g + a) * N_CELLS
                    length = lengths[j]
                    for v in ids:
                        cell = int((length - get_pos(v)) / CELL_LENGTH)
                        if cell < N_CELLS:
                            occ[base + cell] = 1
                    speed_sum += get_mean_speed(lanes[j]) * len(ids)
                    count += len(ids)
                    before = prev[j]
                    if ids != before:  # most steps nothing enters or leaves: no set needed
                        if with_entries and (not before or not set(before).issuperset(ids)):
                            entries[j] = 1
                        prev[j] = ids
                elif prev[j]:
                    prev[j] = ()
            if count:
                reward[g] = speed_sum / (count * SPEED_LIMIT)
        return (
            np.frombuffer(occ, np.uint8).reshape(n, 4 * N_CELLS),
            np.frombuffer(entries, np.uint8).reshape(n, 4),
            np.array(reward, np.float32),
        )

    def reset_prev(self) -> None:
        self.prev = [()] * len(self.flat)
        self.read(with_entries=False)


YELLOW_STEPS = 3
PHASE_NAMES = ("NS_green", "NS_yellow", "EW_green", "EW_yellow")


_ONE_HOT = np.eye(4, dtype=np.uint8)


def observation(occ: np.ndarray, phases: np.ndarray) -> np.ndarray:
    """The 40-bit observations ``[L, 40]`` (float32): 36 occupancy bits + one-hot phase."""
    return np.concatenate((occ, _ONE_HOT[phases]), axis=1, dtype=np.float32)


class _Lights:
    """Keep/switch control of learner lights: a switch goes through 3 s of yellow.

    ``act`` runs before ``simulationStep``: action 1 at a green starts the yellow; actions at
    a yellow are ignored. ``tick`` runs after it: the yellow counts down, and after its 3rd
    simulated second the next green is set (effective from the next step), so the
    observation never shows a light state that SUMO is not about to run.
    """

    def __init__(self, ls, tls: list[str], states: dict, phases):
        self.ls = ls
        self.tls = tls
        self.states = [states[t] for t in tls]
        self.phase = [int(p) for p in phases]
        # the lights now in a yellow (index -> steps left), so tick() visits only those
        self.yellow: dict[int, int] = {}
        for k in range(len(tls)):
            self._set(k)

    def _set(self, k):
        # the raw call skips libsumo's Python wrapper
        self.ls._libsumo.trafficlight_setRedYellowGreenState(
            self.tls[k], self.states[k][self.phase[k]]
        )

    def act(self, actions) -> None:
        if not actions.any():
            return
        phase, yellow = self.phase, self.yellow
        for k in np.flatnonzero(actions).tolist():
            if phase[k] % 2 == 0:
                phase[k] += 1
                yellow[k] = YELLOW_STEPS
                self._set(k)

    def tick(self) -> None:
        yellow = self.yellow
        if not yellow:
            return
        for k in list(yellow):
            left = yellow[k] - 1
            if left:
                yellow[k] = left
            else:
                del yellow[k]
                self.phase[k] = (self.phase[k] + 1) % 4
                self._set(k)


# ----------------------------------------------------------------------------- cores


class GridCore:
    """The global grid simulation (runs where libsumo lives: this process or a worker).

    Config: ``net``, ``routes``, ``tls_add`` (paths), ``observed`` (tls ids whose lanes are
    read, in order), ``lanes`` (their 4 incoming lane ids each), ``controlled`` (whether the
    caller drives the observed lights; else they run the actuated program), ``states`` (tls
    id -> its 4 light states), ``all_tls`` / ``all_lanes`` (every intersection and its
    incoming lanes, for :meth:`state`).
    """

    def __init__(self, net, routes, tls_add, observed, lanes, controlled, states, all_tls=(),
                 all_lanes=()):
        libsumo = import_libsumo()
        self.ls = libsumo
        # the raw call: libsumo.simulationStep also runs TraCI step listeners (never used)
        self._sim_step = libsumo._libsumo.simulation_step
        self.files = (net, routes, tls_add)
        self.observed = list(observed)
        self.controlled = bool(controlled)
        self.states = {k: list(v) for k, v in states.items()}
        self.lanes = [list(x) for x in lanes]
        self.all_tls = list(all_tls)
        self.all_lanes = [list(x) for x in all_lanes]
        self.reader = None
        self.state_reader = None
        self.lights = None
        self.running = False
        self.record_metrics = False
        self._halting = 0
        self._steps = 0

    def reset(self, seed: int, warmup_steps: int = 0):
        """Start a new simulation; returns ``(occ [L,36], phases [L])``."""
        ls = self.ls
        close_any_simulation(self)
        net, routes, tls_add = self.files
        # every vehicle carries SUMO's tripinfo device (time loss, waiting time) for the
        # episode's metrics; it only records (episodes are bitwise the same with or without it)
        start_simulation(ls, sumo_command(seed, net=net, routes=routes, additionals=[tls_add], extra=_GRID_OPTIONS + ("--device.tripinfo.probability", "1")))
        self.running = True
        self._halting = self._steps = 0
        for _ in range(int(warmup_steps)):
            ls.simulationStep()
        if self.reader is None:
            lengths = [[ls.lane.getLength(x) for x in g] for g in self.lanes]
            self.reader = _LaneReader(self.lanes, lengths)
        phases = self._actuated_phases()
        if self.controlled:
            # learners take over from the actuated program in its current (or next) green
            phases = [p + (p % 2) for p in phases]
            phases = [p % 4 for p in phases]
            self.lights = _Lights(ls, self.observed, self.states, phases)
        self.reader.reset_prev()
        occ, _, _ = self.reader.read(with_entries=False)
        return occ, np.array(phases, np.int64)

    def _actuated_phases(self) -> list[int]:
        get = self.ls.trafficlight.getPhase
        return [get(t) for t in self.observed]

    def step(self, actions):
        """Apply ``actions`` (keep 0 / switch 1 per observed light; ignored when the lights
        are not controlled), advance 1 s; returns ``(occ, entries, reward, phases)``."""
        lights = self.lights
        if self.controlled:
            lights.act(actions)
        self._sim_step(0.0)
        if self.record_metrics:
            self._record_step()
        occ, entries, reward = self.reader.read()
        if self.controlled:
            lights.tick()
            phases = np.array(lights.phase, np.int64)
        else:
            phases = np.array(self._actuated_phases(), np.int64)
        return occ, entries, reward, phases

    def enable_metrics(self) -> None:
        """Record the queues at every step from now on (one libsumo call per incoming lane)."""
        self.record_metrics = True
        self._metric_lanes = [ln for g in self.all_lanes for ln in g]
        self._get_halting = import_libsumo()._libsumo.lane_getLastStepHaltingNumber

    def _record_step(self) -> None:
        get = self._get_halting
        self._halting += sum(get(ln) for ln in self._metric_lanes)
        self._steps += 1

    def episode_metrics(self) -> dict:
        """SUMO's tripinfo averages over the vehicles that arrived (time loss = delay, waiting
        time), the vehicles arrived, and the mean number of halting vehicles (speed < 0.1 m/s)
        on the lanes entering the intersections, over the steps (``nan`` unless recording)."""
        get = self.ls.simulation.getParameter
        return {"delay": float(get("", "device.tripinfo.timeLoss")),
                "waiting_time": float(get("", "device.tripinfo.waitingTime")),
                "throughput": float(get("", "device.tripinfo.count")),
                "queue": self._halting / self._steps if self._steps else float("nan")}

    def state(self):
        """The 40-bit observation of every intersection (``all_tls`` order), flattened."""
        ls = self.ls
        if self.state_reader is None:
            lengths = [[ls.lane.getLength(x) for x in g] for g in self.all_lanes]
            self.state_reader = _LaneReader(self.all_lanes, lengths)
        occ, _, _ = self.state_reader.read(with_entries=False)
        known = dict(zip(self.observed, self.lights.phase)) if self.controlled else {}
        get = ls.trafficlight.getPhase
        phases = np.array([known[t] if t in known else get(t) for t in self.all_tls], np.int64)
        return observation(occ, phases).ravel()

    def stats(self) -> dict:
        ls = self.ls
        sim = ls.simulation
        return {
            "time": sim.getTime(),
            "vehicles": ls.vehicle.getIDCount(),
            "pending": len(sim.getPendingVehicles()),
            "arrived_step": sim.getArrivedNumber(),
            "teleports": sim.getStartingTeleportNumber(),
        }

    def render_data(self) -> dict:
        ls = self.ls
        ids = ls.vehicle.getIDList()
        xy = np.array([ls.vehicle.getPosition(v) for v in ids], np.float64).reshape(-1, 2)
        tls = {t: ls.trafficlight.getRedYellowGreenState(t) for t in ls.trafficlight.getIDList()}
        return {"xy": xy, "tls": tls}

    def query(self, domain: str, method: str, *args):
        """Raw libsumo getter (tests and diagnostics), e.g. ``("lane", "getLength", id)``."""
        if not method.startswith("get"):
            raise BadInput(f"only getters can be queried, got {method!r}")
        return getattr(getattr(self.ls, domain), method)(*args)

    def close(self):
        if self.running:
            self.running = False
            self.ls.close()


class LocalCore:
    """``n`` disjoint copies of one intersection in one SUMO network (the local simulator).

    Config: ``net``, ``routes`` (paths), ``n`` (copies), ``states`` (tls id -> its 4 light
    states), ``route_ids[k][approach][turn]``.
    """

    def __init__(self, net, routes, n, states, route_ids):
        libsumo = import_libsumo()
        self.ls = libsumo
        self._sim_step = libsumo._libsumo.simulation_step
        self.files = (net, routes)
        self.n = int(n)
        self.tls = [f"c{k}" for k in range(self.n)]
        self.states = states
        self.route_ids = route_ids
        self.lanes = [[f"c{k}_{a}__c{k}_0" for a in "NESW"] for k in range(self.n)]
        self.reader = None
        self.lights = None
        self.running = False
        self.counters = [0] * self.n

    def reset(self, seed: int):
        """Start a new episode (all lights north-south green); returns ``(occ, phases)``.

        A running simulation is reused: its vehicles (and pending insertions) are removed,
        which costs ~0.1 ms instead of ~10 ms for a restart -- a third of a 300-step LS
        episode. Nothing in the LS draws from SUMO's random numbers (deterministic IDM, no
        speed deviation, fixed depart lane/position/speed; the turns are drawn by the
        caller), and the dynamics do not depend on the clock, so an episode after this
        soft reset equals one after a restart (checked in the tests).
        """
        ls = self.ls
        soft = False
        if self.running:
            try:
                remove = ls.vehicle.remove
                for v in ls.vehicle.getIDList():
                    remove(v)
                for v in ls.simulation.getPendingVehicles():
                    remove(v)
                soft = True
            except Exception:
                soft = False
        if not soft:
            close_any_simulation(self)
            # a car that cannot be inserted at once is dropped: in the GS it would simply
            # not have entered the lane at this step
            net, routes = self.files
            start_simulation(ls, sumo_command(seed, net=net, routes=routes, extra=_GRID_OPTIONS + ("--max-depart-delay", "0")))
            self.running = True
            self.counters = [0] * self.n
        if self.reader is None:
            lengths = [[ls.lane.getLength(x) for x in g] for g in self.lanes]
            self.reader = _LaneReader(self.lanes, lengths)
        self.lights = _Lights(ls, self.tls, self.states, [0] * self.n)
        self.reader.reset_prev()
        occ, _, _ = self.reader.read(with_entries=False)
        return occ, np.zeros(self.n, np.int64)

    def hard_reset(self, seed: int):
        """Restart SUMO (tests: to compare with the soft reset)."""
        self.close()
        return self.reset(seed)

    def step(self, actions, inserts):
        """``actions`` per copy; ``inserts``: (copy, approach, turn) triples of cars to put
        at the start of the incoming lanes. Returns ``(occ, entries, reward, phases)``."""
        ls = self.ls
        self.lights.act(actions)
        if inserts:
            # raw call: (id, route, type, depart, departLane, departPos, departSpeed)
            add = ls._libsumo.vehicle_add
            route_ids, counters = self.route_ids, self.counters
            for k, a, t in inserts:
                # ids numbered per copy, zero-padded: SUMO breaks ties by comparing vehicle
                # ids as strings, so a copy's cars must sort alike in any batch of copies
                counters[k] += 1
                add(f"c{k}.{counters[k]:09d}", route_ids[k][a][t], "car", "now", "0", "base", "10")
        self._sim_step(0.0)
        occ, entries, reward = self.reader.read()
        self.lights.tick()
        return occ, entries, reward, np.array(self.lights.phase, np.int64)

    def stats(self) -> dict:
        return GridCore.stats(self)

    def render_data(self) -> dict:
        return GridCore.render_data(self)

    def query(self, domain: str, method: str, *args):
        return GridCore.query(self, domain, method, *args)

    def close(self):
        if self.running:
            self.running = False
            self.ls.close()
