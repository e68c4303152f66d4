"""Where a SUMO simulation runs: this process (under a lease) or a worker process.

Shared by every SUMO domain (the grid, real city networks). libsumo holds ONE simulation per
process, and a second ``libsumo.start()`` silently replaces the first. Everything that touches
libsumo therefore lives in a *simulation core* (a domain's class, named to :class:`SimHandle`
as ``"package.module:Class"`` so a worker can import it) whose methods each do one whole step's
work, and a
:class:`SimHandle` runs a core

* **in-process** (``backend="inprocess"``): the core calls libsumo directly. A module-level
  *lease* allows one live in-process simulation per process; asking for a second one raises
  :class:`SimulationBusyError` (also when someone else started a libsumo simulation outside
  this module: ``libsumo.simulation.isLoaded()``);
* in a **worker process** (``backend="worker"``): a :class:`ials_zoo.runtime.processes.Worker` that
  holds the core, forked from a :class:`ials_zoo.runtime.zygote.Zygote` that imported libsumo and
  the core's module but never started a simulation (nothing of the parent inherited; it starts
  in milliseconds, not the second a fresh interpreter takes to import them); one pipe round
  trip per call over two dedicated pipes (SUMO's own console output cannot corrupt the
  protocol). The worker dies with this process and exits when its pipe closes; it sends a
  heartbeat every :data:`ials_zoo.runtime.processes.HEARTBEAT_SECONDS`. The parent raises
  :class:`WorkerDiedError` when the worker dies, and :class:`WorkerUnresponsiveError` (and
  kills it) when it is stopped, stops beating for ``unresponsive_after`` seconds (a hung
  process) or a call outlasts ``timeout``. The next ``reset`` spawns a new worker;
* ``backend="auto"`` (default): in-process when this process holds no live simulation,
  otherwise a worker -- decided once, when the handle is created.

Errors raised by SUMO (``libsumo.TraCIException`` / ``FatalTraCIError``) come out as
:class:`SimulationError` with SUMO's message, in both modes. Closing a handle ends its
simulation (or worker) and frees the lease.
"""

from __future__ import annotations

import atexit
import importlib
import os
import sys
import threading
import weakref

from ials_zoo.errors import BadInput
from ials_zoo.runtime.processes import Worker, WorkerError

BACKENDS = ("auto", "inprocess", "worker")


class SimulationError(RuntimeError):
    """An error inside the SUMO simulation (SUMO's message included)."""


class SimulationBusyError(SimulationError):
    """This process already runs a live libsumo simulation."""


class WorkerDiedError(SimulationError):
    """The worker process that held the simulation died."""


class WorkerUnresponsiveError(WorkerDiedError):
    """The worker process stopped answering (stopped, hung, or too slow); it was killed."""


# ----------------------------------------------------------------------------- libsumo


def import_libsumo():
    """``libsumo``, imported without its pyarrow version warning: libsumo prints it whenever a
    pyarrow is installed (Ray installs one) that differs from the one SUMO was built against,
    but only SUMO's Parquet outputs use arrow, and the zoo writes none. The switch it reads
    (``LIBSUMO_AS_TRACI=quiet``) also makes ``import traci`` use libsumo, so it is set only
    while libsumo is imported."""

    if "libsumo" in sys.modules:
        return sys.modules["libsumo"]
    before = os.environ.get("LIBSUMO_AS_TRACI")
    os.environ["LIBSUMO_AS_TRACI"] = "quiet"
    try:
        import libsumo
    finally:
        if before is None:
            del os.environ["LIBSUMO_AS_TRACI"]
        else:
            os.environ["LIBSUMO_AS_TRACI"] = before
    return libsumo


# ----------------------------------------------------------------------------- the lease

_lease_lock = threading.Lock()
_lease_owner: int | None = None  # id() of the SimHandle holding the in-process simulation


def inprocess_available() -> bool:
    """True when this process could start an in-process libsumo simulation now."""
    if _lease_owner is not None:
        return False
    return not import_libsumo().simulation.isLoaded()


def _acquire(owner: int) -> None:
    global _lease_owner
    with _lease_lock:
        if _lease_owner is not None and _lease_owner != owner:
            raise SimulationBusyError(
                "this process already holds a live libsumo simulation (libsumo allows one "
                "per process); close the other env first or use backend='worker' or 'auto'"
            )
        if _lease_owner is None and import_libsumo().simulation.isLoaded():
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


def wrap_sumo_error(exc: BaseException) -> BaseException:
    """A libsumo exception as a :class:`SimulationError`; anything else unchanged."""
    if type(exc).__module__.startswith("libsumo"):
        return SimulationError(f"SUMO error ({type(exc).__name__}): {exc}")
    return exc


def call_core(core, method: str, args: tuple):
    """``core.method(*args)`` with SUMO's errors as :class:`SimulationError` (in this process
    or in a worker: the same errors either way)."""
    try:
        return getattr(core, method)(*args)
    except Exception as e:
        w = wrap_sumo_error(e)
        if w is e:
            raise
        raise w from e


def _core_class(path: str):
    module, _, name = path.partition(":")
    return getattr(importlib.import_module(module), name)


def check_core_path(path) -> str:
    """``path`` if it reads ``"package.module:Class"``, else a BadInput naming the form."""
    if not (isinstance(path, str) and path.count(":") == 1 and all(path.split(":"))):
        raise BadInput(f"a simulation core is named 'package.module:Class', got {path!r}")
    return path


# ----------------------------------------------------------------------------- handle

_live_workers: weakref.WeakSet[SimHandle] = weakref.WeakSet()


@atexit.register
def _kill_workers():
    for h in list(_live_workers):
        h._kill()


class _WorkerCore:
    """A core in a :class:`~ials_zoo.runtime.processes.Worker` (holding this worker's lease), whose
    SUMO errors come back as :class:`SimulationError` with SUMO's message."""

    def __init__(self, core: str, config: dict):
        _acquire(-1)
        self.core = _core_class(core)(**config)

    def call(self, method: str, args: tuple):
        return call_core(self.core, method, args)

    def close(self):
        self.core.close()


class SimHandle:
    """Runs one core in-process or in a worker process (see the module docstring).

    Args:
        core: the core class as ``"package.module:Class"`` (importable in a fresh worker).
        config: keyword arguments of the core (picklable).
        backend: ``"auto"``, ``"inprocess"`` or ``"worker"``.
        timeout: seconds one worker call may take at most.
        unresponsive_after: seconds without a heartbeat after which a worker is given up.
        load_seconds: how long a call of ``loads`` may load a network
            (:func:`~ials_zoo.sumo.command.load_budget`): SUMO holds Python's lock while it
            loads, so the worker sends no heartbeat; while its CPU time grows it is loading, and
            is given up only past this budget (and ``timeout`` grows by it). A worker that
            neither beats nor computes is named as before.
        loads: the core's methods that start SUMO (load the network).
    """

    def __init__(self, core: str, config: dict, backend: str = "auto", timeout: float = 120.0,
                 unresponsive_after: float = 5.0, load_seconds: float = 0.0, loads: tuple[str, ...] = ("reset",)):
        if backend not in BACKENDS:
            raise BadInput(f"unknown backend {backend!r}; expected one of {BACKENDS}")
        self.core_name = check_core_path(core)
        self.config = config
        self.timeout = float(timeout)
        self.unresponsive_after = float(unresponsive_after)
        self.load_seconds, self.loads = max(float(load_seconds), 0.0), tuple(loads)
        self._core = None
        self._worker: Worker | None = None
        self._spare: Worker | None = None  # a worker started ahead of the next restart(spare=True)
        self.closed = False
        if backend == "auto":
            backend = "inprocess" if inprocess_available() else "worker"
        if backend == "inprocess":
            _acquire(id(self))
        self.mode = backend

    # -- in-process
    def _local_core(self):
        if self._core is None:
            self._core = _core_class(self.core_name)(**self.config)
        return self._core

    # -- worker
    def _new_worker(self) -> Worker:
        # forked from a process that imported libsumo and the core but never started a
        # simulation: as fresh as a new interpreter for SUMO, without its second of imports
        preload = ("ials_zoo.sumo.lease:import_libsumo", self.core_name.partition(":")[0])
        try:
            return Worker(_WorkerCore, (self.core_name, self.config), name="SUMO worker",
                          unresponsive_after=self.unresponsive_after, preload=preload)
        except WorkerError as exc:  # its zygote died, stopped or did not answer
            raise WorkerDiedError(f"could not start a SUMO worker: {exc}") from None

    def _spawn(self):
        # a spare started earlier (restart(spare=True)) has done its imports meanwhile
        self._worker, self._spare = (self._spare or self._new_worker()), None
        _live_workers.add(self)
        try:
            self._ask(self._worker.started, self.timeout)
        except BaseException:  # a SUMO error or Ctrl-C while starting: no half-started worker stays
            self._kill()
            raise

    def _ask(self, method, *args, **kwargs):
        """``method(*args, **kwargs)`` of the worker, its errors as this module's."""
        try:
            return method(*args, **kwargs)
        except WorkerError as exc:
            if isinstance(exc, BadInput):
                raise BadInput(str(exc)) from None
            if exc.kind == "failed":
                name, message, trace = exc.remote
                if name == "SimulationError":
                    raise SimulationError(message) from None
                raise SimulationError(f"error in the SUMO worker: {name}: {message}\n{trace}") from None
            pid = self._worker.pid
            self._kill()
            if exc.kind == "died":
                raise WorkerDiedError(f"the SUMO worker process (pid {pid}) died ({exc}); the episode is lost, "
                                      "call reset() to start a new worker") from None
            limit = self.timeout + self.load_seconds if self.load_seconds else self.timeout
            why = {"stopped": "is stopped and sends no heartbeat (SIGSTOP or a debugger)",
                   "unresponsive": "sent no heartbeat for "
                                   f"{self.unresponsive_after:.1f} s (stopped or hung"
                                   + (f"; a network's load may take {self.load_seconds:.0f} s while its CPU "
                                      "time grows" if self.load_seconds else "") + ")"}.get(
                exc.kind, f"did not answer within {limit:.0f} s")
            raise WorkerUnresponsiveError(f"the SUMO worker (pid {pid}) {why}; it was killed. The episode is "
                                          "lost: call reset() to start a new worker") from None

    def _kill(self):
        for worker in (self._worker, self._spare):
            if worker is not None:
                worker.close(kill=True)
        self._worker = self._spare = None
        _live_workers.discard(self)

    def restart(self, spare: bool = False) -> None:
        """End this handle's worker (if any): the next ``reset`` call runs in a fresh process.
        ``spare``: that process is one started beforehand, and a new spare starts now, so that
        its interpreter start overlaps the episode about to run (not the next reset)."""
        if self.closed:
            raise SimulationError("this simulation handle is closed")
        if self.mode != "worker":
            return
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.close(kill=True)
        if spare:
            if self._spare is None:
                self._spare = self._new_worker()
            self._spawn()
            self._spare = self._new_worker()
            _live_workers.add(self)

    @property
    def worker_pid(self) -> int | None:
        return self._worker.pid if self._worker is not None else None

    # -- public
    def call(self, method: str, *args):
        """Run ``core.method(*args)`` where the core lives and return its result."""
        if self.closed:
            raise SimulationError("this simulation handle is closed")
        if self.mode == "inprocess":
            return call_core(self._local_core(), method, args)
        if self._worker is None:
            if method != "reset" and method not in self.loads:  # a call that starts SUMO starts its worker
                raise WorkerDiedError(
                    "no live SUMO worker (it died or was never started); call reset() first"
                )
            self._spawn()
        loading = self.load_seconds if method in self.loads else 0.0
        try:
            return self._ask(self._worker.call, "call", method, args, timeout=self.timeout + loading,
                             busy_for=loading)
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
            workers, self._worker, self._spare = (self._worker, self._spare), None, None
            for worker in workers:
                if worker is not None:
                    worker.close()
            _live_workers.discard(self)

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


class PlainHandle:
    """A core that holds no SUMO simulation (an array local simulator, :mod:`ials_zoo.sumo_net.arrays_core`)
    behind :class:`SimHandle`'s calls: always in this process, no lease taken, so a SUMO
    simulation of this process stays where it is. ``backend`` and the budgets are accepted and
    ignored."""

    mode = "inprocess"

    def __init__(self, core: str, config: dict, backend: str = "auto", **_budgets):
        if backend not in BACKENDS:
            raise BadInput(f"unknown backend {backend!r}; expected one of {BACKENDS}")
        self.core_name = check_core_path(core)
        self._core = _core_class(self.core_name)(**config)
        self.closed = False

    def call(self, method: str, *args):
        if self.closed:
            raise SimulationError("this simulation was closed")
        return call_core(self._core, method, args)

    def restart(self, spare: bool = False) -> None:
        """Nothing to restart: the core holds no simulation."""

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._core.close()


__all__ = [
    "BACKENDS",
    "PlainHandle",
    "SimHandle",
    "SimulationBusyError",
    "SimulationError",
    "WorkerDiedError",
    "WorkerUnresponsiveError",
    "inprocess_available",
]
