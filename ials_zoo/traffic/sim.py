"""SUMO simulation cores and the libsumo-safe backend that runs them.

libsumo holds ONE simulation per process, and a second ``libsumo.start()`` silently replaces
the first. Everything that touches libsumo therefore lives in a *simulation core* (a class
below) whose methods each do one whole step's work and return numpy arrays, so an env needs
exactly one core call per step. A :class:`SimHandle` runs a core

* **in-process** (``backend="inprocess"``): the core calls libsumo directly. A module-level
  *lease* allows one live in-process simulation per process; asking for a second one raises
  :class:`SimulationBusyError` (also when someone else started a libsumo simulation outside
  this module: ``libsumo.simulation.isLoaded()``);
* in a **worker process** (``backend="worker"``): a fresh ``python -m
  ials_zoo.traffic._worker`` subprocess (a new interpreter, so nothing of the parent -- its
  ``__main__``, its libsumo state -- is inherited) that holds the core; one pipe round trip
  per call (``multiprocessing.connection.Connection`` over two dedicated pipes, so SUMO's own
  console output cannot corrupt the protocol). The parent waits with ``poll(timeout)`` and
  checks that the worker is alive, so a killed worker raises :class:`WorkerDiedError` instead
  of hanging; the next ``start`` spawns a new worker. The worker exits when its pipe closes
  (parent closed the handle or died) and is killed at interpreter exit (daemon-like);
* ``backend="auto"`` (default): in-process when this process holds no live simulation,
  otherwise a worker -- decided once, when the handle is created.

Errors raised by SUMO (``libsumo.TraCIException`` / ``FatalTraCIError``) come out as
:class:`SimulationError` with SUMO's message, in both modes. Closing a handle ends its
simulation (or worker) and frees the lease.
"""

from __future__ import annotations

import atexit
import os
import subprocess
import sys
import threading
import traceback
import weakref
from multiprocessing.connection import Connection

import numpy as np

from ials_zoo.traffic.network import CELL_LENGTH, N_CELLS, SPEED_LIMIT

BACKENDS = ("auto", "inprocess", "worker")


class SimulationError(RuntimeError):
    """An error inside the SUMO simulation (SUMO's message included)."""


class SimulationBusyError(SimulationError):
    """This process already runs a live libsumo simulation."""


class WorkerDiedError(SimulationError):
    """The worker process that held the simulation died."""


# ----------------------------------------------------------------------------- the lease

_lease_lock = threading.Lock()
_lease_owner: int | None = None  # id() of the SimHandle holding the in-process simulation


def inprocess_available() -> bool:
    """True when this process could start an in-process libsumo simulation now."""
    if _lease_owner is not None:
        return False
    import libsumo

    return not libsumo.simulation.isLoaded()


def _acquire(owner: int) -> None:
    global _lease_owner
    with _lease_lock:
        if _lease_owner is not None and _lease_owner != owner:
            raise SimulationBusyError(
                "this process already holds a live libsumo simulation (libsumo allows one "
                "per process); close the other env first or use backend='worker' or 'auto'"
            )
        import libsumo

        if _lease_owner is None and libsumo.simulation.isLoaded():
            raise SimulationBusyError(
                "a libsumo simulation started outside ials_zoo is live in this process; "
                "use backend='worker' or 'auto'"
            )
        _lease_owner = owner


def _release(owner: int) -> None:
    global _lease_owner
    with _lease_lock:
        if _lease_owner == owner:
            _lease_owner = None


def _wrap_sumo_error(exc: BaseException) -> BaseException:
    if type(exc).__module__.startswith("libsumo"):
        return SimulationError(f"SUMO error ({type(exc).__name__}): {exc}")
    return exc


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
        from libsumo import _libsumo as L

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


def _sumo_cmd(net, routes, additionals, seed, extra=()):
    cmd = ["sumo", "-n", net, "-r", routes]
    if additionals:
        cmd += ["-a", ",".join(additionals)]
    cmd += [
        "--step-length", "1", "--seed", str(int(seed)), "--no-step-log", "true",
        "--no-warnings", "true", "--duration-log.disable", "true",
        "--device.rerouting.probability", "0", *extra,
    ]  # fmt: skip
    return cmd


# ----------------------------------------------------------------------------- cores


def _close_any_simulation(core) -> None:
    """Close the core's simulation before a fresh start, also one that a SUMO error left
    half-closed (loaded but no longer marked running)."""
    if core.running or core.ls.simulation.isLoaded():
        core.running = False
        try:
            core.ls.close()
        except Exception:
            pass


class GridCore:
    """The global grid simulation (runs where libsumo lives: this process or a worker).

    Config: ``net``, ``routes``, ``tls_add`` (paths), ``observed`` (tls ids whose lanes are
    read, in order), ``lanes`` (their 4 incoming lane ids each), ``controlled`` (whether the
    caller drives the observed lights; else they run the actuated program), ``states`` (tls
    id -> its 4 light states).
    """

    def __init__(self, net, routes, tls_add, observed, lanes, controlled, states):
        import libsumo

        self.ls = libsumo
        # the raw call: libsumo.simulationStep also runs TraCI step listeners (never used)
        self._sim_step = libsumo._libsumo.simulation_step
        self.files = (net, routes, tls_add)
        self.observed = list(observed)
        self.controlled = bool(controlled)
        self.states = {k: list(v) for k, v in states.items()}
        self.lanes = [list(x) for x in lanes]
        self.reader = None
        self.lights = None
        self.running = False

    def reset(self, seed: int, warmup_steps: int = 0):
        """Start a new simulation; returns ``(occ [L,36], phases [L])``."""
        ls = self.ls
        _close_any_simulation(self)
        net, routes, tls_add = self.files
        ls.start(_sumo_cmd(net, routes, [tls_add], seed))
        self.running = True
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
        ls = self.ls
        lights = self.lights
        if self.controlled:
            lights.act(actions)
        self._sim_step(0.0)
        occ, entries, reward = self.reader.read()
        if self.controlled:
            lights.tick()
            phases = np.array(lights.phase, np.int64)
        else:
            phases = np.array(self._actuated_phases(), np.int64)
        return occ, entries, reward, phases

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
            raise ValueError(f"only getters can be queried, got {method!r}")
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
        import libsumo

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
        self.counter = 0

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
            _close_any_simulation(self)
            # a car that cannot be inserted at once is dropped: in the GS it would simply
            # not have entered the lane at this step
            ls.start(_sumo_cmd(*self.files, [], seed, extra=("--max-depart-delay", "0")))
            self.running = True
            self.counter = 0
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
            route_ids = self.route_ids
            for k, a, t in inserts:
                self.counter += 1
                add(f"v{self.counter}", route_ids[k][a][t], "car", "now", "0", "base", "10")
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


# ----------------------------------------------------------------------------- handle

_live_workers: "weakref.WeakSet[SimHandle]" = weakref.WeakSet()


@atexit.register
def _kill_workers():
    for h in list(_live_workers):
        h._kill()


class SimHandle:
    """Runs one core in-process or in a worker process (see the module docstring).

    Args:
        core: name of a core class of this module (``"GridCore"`` / ``"LocalCore"``).
        config: keyword arguments of the core (picklable).
        backend: ``"auto"``, ``"inprocess"`` or ``"worker"``.
        timeout: seconds to wait for one worker call before giving up (the worker is
            checked for liveness every 0.2 s meanwhile).
    """

    def __init__(self, core: str, config: dict, backend: str = "auto", timeout: float = 600.0):
        if backend not in BACKENDS:
            raise ValueError(f"unknown backend {backend!r}; expected one of {BACKENDS}")
        self.core_name = core
        self.config = config
        self.timeout = timeout
        self._core = None
        self._proc = None
        self._conn_r = self._conn_w = None
        self.closed = False
        if backend == "auto":
            backend = "inprocess" if inprocess_available() else "worker"
        if backend == "inprocess":
            _acquire(id(self))
        self.mode = backend

    # -- in-process
    def _local_core(self):
        if self._core is None:
            self._core = getattr(sys.modules[__name__], self.core_name)(**self.config)
        return self._core

    # -- worker
    def _spawn(self):
        r_child, w_parent = os.pipe()  # parent -> child
        r_parent, w_child = os.pipe()  # child -> parent
        env = dict(os.environ)
        env.setdefault("OMP_NUM_THREADS", "1")
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "ials_zoo.traffic._worker", str(r_child), str(w_child)],
                pass_fds=(r_child, w_child),
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                env=env,
                close_fds=True,
            )
        finally:
            os.close(r_child)
            os.close(w_child)
        self._conn_w = Connection(w_parent, readable=False)
        self._conn_r = Connection(r_parent, writable=False)
        _live_workers.add(self)
        try:
            self._send(("init", self.core_name, self.config))
            self._recv()
        except BaseException:
            self._kill()
            raise

    def _send(self, msg):
        try:
            self._conn_w.send(msg)
        except (BrokenPipeError, OSError) as e:
            self._died(e)

    def _recv(self):
        waited = 0.0
        while not self._conn_r.poll(0.2):
            waited += 0.2
            if self._proc.poll() is not None:
                self._died(None)
            if waited > self.timeout:
                self._kill()
                raise WorkerDiedError(
                    f"the SUMO worker did not answer within {self.timeout:.0f} s; killed it"
                )
        try:
            status, payload = self._conn_r.recv()
        except (EOFError, OSError) as e:
            self._died(e)
        if status == "ok":
            return payload
        name, msg, tb = payload
        if name == "SimulationError":
            raise SimulationError(msg)
        raise SimulationError(f"error in the SUMO worker: {name}: {msg}\n{tb}")

    def _died(self, cause):
        code = self._proc.poll() if self._proc is not None else None
        self._kill()
        raise WorkerDiedError(
            f"the SUMO worker process died (exit code {code}); the episode is lost, call "
            "reset() to start a new worker"
        ) from cause

    def _kill(self):
        proc, self._proc = self._proc, None
        for c in (self._conn_r, self._conn_w):
            if c is not None:
                try:
                    c.close()
                except OSError:
                    pass
        self._conn_r = self._conn_w = None
        if proc is not None:
            if proc.poll() is None:
                proc.kill()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                pass
        _live_workers.discard(self)

    @property
    def worker_pid(self) -> int | None:
        return self._proc.pid if self._proc is not None else None

    # -- public
    def call(self, method: str, *args):
        """Run ``core.method(*args)`` where the core lives and return its result."""
        if self.closed:
            raise SimulationError("this simulation handle is closed")
        if self.mode == "inprocess":
            try:
                return getattr(self._local_core(), method)(*args)
            except Exception as e:
                w = _wrap_sumo_error(e)
                if w is e:
                    raise
                raise w from e
        if self._proc is None:
            if method not in ("reset",):
                raise WorkerDiedError(
                    "no live SUMO worker (it died or was never started); call reset() first"
                )
            self._spawn()
        try:
            self._send(("call", method, args))
            return self._recv()
        except SimulationError:
            raise  # the worker answered (an error) or is already gone: nothing out of sync
        except BaseException:
            # e.g. KeyboardInterrupt while waiting: the answer would arrive out of turn later,
            # so this worker is dropped; the next reset() starts a fresh one
            self._kill()
            raise

    def close(self) -> None:
        """End the simulation (or the worker) and free the in-process lease."""
        if self.closed:
            return
        self.closed = True
        if self.mode == "inprocess":
            try:
                if self._core is not None:
                    self._core.close()
            finally:
                self._core = None
                _release(id(self))
        else:
            if self._proc is not None and self._proc.poll() is None:
                try:
                    self._conn_w.send(("exit", None, None))
                    self._proc.wait(timeout=2)
                except Exception:
                    pass
            self._kill()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def _worker_main(r_fd: int, w_fd: int) -> None:
    conn_r = Connection(r_fd, writable=False)
    conn_w = Connection(w_fd, readable=False)
    core = None
    while True:
        try:
            kind, a, b = conn_r.recv()
        except EOFError:
            break
        if kind == "exit":
            break
        try:
            if kind == "init":
                _acquire(-1)
                core = getattr(sys.modules[__name__], a)(**b)
                result = None
            else:
                result = getattr(core, a)(*b)
            conn_w.send(("ok", result))
        except Exception as e:
            w = _wrap_sumo_error(e)
            conn_w.send(("err", (type(w).__name__, str(w), traceback.format_exc())))
    if core is not None:
        try:
            core.close()
        except Exception:
            pass


