"""Where a SUMO simulation runs: this process (under a lease) or a worker process.

libsumo holds ONE simulation per process, and a second ``libsumo.start()`` silently replaces
the first. Everything that touches libsumo therefore lives in a *simulation core*
(:mod:`ials_zoo.traffic.cores`) whose methods each do one whole step's work, and a
:class:`SimHandle` runs a core

* **in-process** (``backend="inprocess"``): the core calls libsumo directly. A module-level
  *lease* allows one live in-process simulation per process; asking for a second one raises
  :class:`SimulationBusyError` (also when someone else started a libsumo simulation outside
  this module: ``libsumo.simulation.isLoaded()``);
* in a **worker process** (``backend="worker"``): a fresh ``python -m
  ials_zoo.traffic._worker`` interpreter (nothing of the parent is inherited) that holds the
  core; one pipe round trip per call over two dedicated pipes (SUMO's own console output
  cannot corrupt the protocol). The worker dies with this process
  (:func:`ials_zoo.processes.die_with_parent`) and exits when its pipe closes. While a call
  is under way the worker sends a heartbeat every :data:`HEARTBEAT_SECONDS`; the parent
  raises :class:`WorkerDiedError` when the worker dies, and :class:`WorkerUnresponsiveError`
  (and kills it) when it stops beating for ``unresponsive_after`` seconds (a stopped or hung
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
import subprocess
import sys
import threading
import time
import traceback
import weakref
from multiprocessing.connection import Connection

from ials_zoo.processes import sigint_ignored_at_birth

BACKENDS = ("auto", "inprocess", "worker")
HEARTBEAT_SECONDS = 0.5
CORES_MODULE = "ials_zoo.traffic.cores"


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
    import sys

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


def _core_class(name: str):
    return getattr(importlib.import_module(CORES_MODULE), name)


# ----------------------------------------------------------------------------- handle

_live_workers: weakref.WeakSet[SimHandle] = weakref.WeakSet()


@atexit.register
def _kill_workers():
    for h in list(_live_workers):
        h._kill()


class SimHandle:
    """Runs one core in-process or in a worker process (see the module docstring).

    Args:
        core: name of a core class of :mod:`ials_zoo.traffic.cores`.
        config: keyword arguments of the core (picklable).
        backend: ``"auto"``, ``"inprocess"`` or ``"worker"``.
        timeout: seconds one worker call may take at most.
        unresponsive_after: seconds without a heartbeat after which a worker is given up.
    """

    def __init__(self, core: str, config: dict, backend: str = "auto", timeout: float = 120.0,
                 unresponsive_after: float = 5.0):
        if backend not in BACKENDS:
            raise ValueError(f"unknown backend {backend!r}; expected one of {BACKENDS}")
        self.core_name = core
        self.config = config
        self.timeout = float(timeout)
        self.unresponsive_after = float(unresponsive_after)
        self._core = None
        self._proc = None
        self._conn_r = self._conn_w = None
        self._beat_fd = None
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
    def _spawn(self):
        r_child, w_parent = os.pipe()  # parent -> child
        r_parent, w_child = os.pipe()  # child -> parent
        beat_r, beat_w = os.pipe()  # child -> parent heartbeats
        env = dict(os.environ)
        env.setdefault("OMP_NUM_THREADS", "1")
        try:
            with sigint_ignored_at_birth():
                self._proc = subprocess.Popen(
                    [sys.executable, "-m", "ials_zoo.traffic._worker", str(r_child), str(w_child), str(beat_w)],
                    pass_fds=(r_child, w_child, beat_w),
                    stdin=subprocess.DEVNULL,
                    stdout=subprocess.DEVNULL,
                    env=env,
                    close_fds=True,
                )
        finally:
            for fd in (r_child, w_child, beat_w):
                os.close(fd)
        os.set_blocking(beat_r, False)
        self._beat_fd = beat_r
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

    def _heard(self) -> bool:
        """Drain the heartbeat pipe; True when the worker beat since the last look."""
        heard = False
        while True:
            try:
                chunk = os.read(self._beat_fd, 4096)
            except BlockingIOError:
                return heard
            except OSError:
                return heard
            if not chunk:
                return heard
            heard = True

    def _recv(self):
        start = last_beat = time.monotonic()
        self._heard()  # beats from before this call say nothing about it
        while not self._conn_r.poll(0.1):
            now = time.monotonic()
            if self._proc.poll() is not None:
                self._died(None)
            if self._heard():
                last_beat = now
            silent = now - last_beat
            if silent > self.unresponsive_after or now - start > self.timeout:
                pid = self._proc.pid
                self._kill()
                why = (f"sent no heartbeat for {silent:.1f} s (stopped or hung)"
                       if silent > self.unresponsive_after else f"did not answer within {self.timeout:.0f} s")
                raise WorkerUnresponsiveError(
                    f"the SUMO worker (pid {pid}) {why}; it was killed. The episode is lost: call "
                    "reset() to start a new worker"
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
        if self._beat_fd is not None:
            try:
                os.close(self._beat_fd)
            except OSError:
                pass
            self._beat_fd = None
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
                w = wrap_sumo_error(e)
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


def _heartbeat(fd: int) -> None:
    while True:
        try:
            os.write(fd, b".")
        except OSError:
            return
        time.sleep(HEARTBEAT_SECONDS)


def worker_main(r_fd: int, w_fd: int, beat_fd: int | None = None) -> None:
    """The loop of a worker process: read a request, run it on the core, answer."""
    from ials_zoo.processes import die_with_parent

    die_with_parent(ignore_sigint=True)
    if beat_fd is not None:
        threading.Thread(target=_heartbeat, args=(beat_fd,), daemon=True).start()
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
                core = _core_class(a)(**b)
                result = None
            else:
                result = getattr(core, a)(*b)
            conn_w.send(("ok", result))
        except Exception as e:
            w = wrap_sumo_error(e)
            conn_w.send(("err", (type(w).__name__, str(w), traceback.format_exc())))
    if core is not None:
        try:
            core.close()
        except Exception:
            pass


__all__ = [
    "BACKENDS",
    "SimHandle",
    "SimulationBusyError",
    "SimulationError",
    "WorkerDiedError",
    "WorkerUnresponsiveError",
    "inprocess_available",
]
