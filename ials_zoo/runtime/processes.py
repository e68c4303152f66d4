"""Child processes that never outlive their parent, and pools that never hang on shutdown.

Every process the zoo starts (SUMO workers, evaluation and collection pools, the env workers
of a single-agent traffic run, the jobs of a study, DIALS learners) calls
:func:`die_with_parent` first thing: on Linux the kernel then sends it ``SIGKILL`` when the
parent dies, however the parent dies (Ctrl-C, ``SIGTERM``, ``kill -9``). Elsewhere a child
notices its parent's death at its next pipe read (EOF).

:func:`spawn_pool` is a ``ProcessPoolExecutor`` of fresh interpreters (``spawn``: nothing of a
live libsumo simulation is inherited) whose workers die with this process and ignore
``SIGINT`` (a Ctrl-C is the parent's to handle: it stops the pool, the workers do not each
raise ``KeyboardInterrupt`` half-way through a task). :func:`shutdown_pool` stops one without
waiting on a worker that no longer answers.

:class:`Worker` is the one protocol for a long-lived worker of ours: an object built in a
fresh interpreter and called by method name, ``call(method, *args)``, with a heartbeat, a
death and stop signal and a timeout: DIALS's shards (:mod:`ials_zoo.dials.backends`), IPPO's
GS copies (:mod:`ials_zoo.learners.gs_vec`), SUMO simulations (:mod:`ials_zoo.sumo.lease`)
and the env workers of SB3's vector envs (:mod:`ials_zoo.single_agent`). Pools of short tasks
(collection, evaluation) stay ``concurrent.futures`` pools (:func:`spawn_pool`).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import ctypes
import multiprocessing
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import threading
import time
import traceback
from multiprocessing.connection import Connection

from ials_zoo.errors import BadInput
from ials_zoo.runtime import zygote as zygotes
from ials_zoo.runtime.children import fresh_interpreter, process_cpu_ticks, process_state

_PR_SET_PDEATHSIG = 1
_M_TRIM_THRESHOLD, _M_MMAP_MAX = -1, -4  # glibc <malloc.h>


def keep_freed_memory(trim_bytes: int = 1 << 30) -> bool:
    """Let glibc serve every block from its heap (no ``mmap`` per large block) and keep up to
    ``trim_bytes`` of freed heap for reuse instead of returning it to the kernel (``mallopt``;
    no-op elsewhere). Torch frees and reallocates the same
    few-hundred-kB tensors thousands of times per second when it trains a recurrent AIP; by
    default each goes back to the kernel and returns as fresh zeroed pages, and the page
    faults cost more than the arithmetic (measured: 36 stacked GRU AIPs trained 2.7x faster,
    system time 17 s -> 0.6 s). Memory stays at its peak while the process lives.
    Returns whether the allocator took the setting."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None)
        ok = libc.mallopt(_M_MMAP_MAX, 0) == 1
        return bool(libc.mallopt(_M_TRIM_THRESHOLD, int(trim_bytes)) == 1 and ok)
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        return False


def die_with_parent(sig: int = signal.SIGKILL, ignore_sigint: bool = False) -> None:
    """Ask the kernel to send ``sig`` to this process when its parent dies (Linux), and exit
    at once if the parent is already gone. ``ignore_sigint``: leave Ctrl-C to the parent."""
    if ignore_sigint:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        parent = os.getppid()
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0)
        except (OSError, AttributeError):  # pragma: no cover - no prctl: rely on pipe EOF
            return
        if os.getppid() != parent or parent == 1:  # the parent died before prctl took effect
            os._exit(1)


@contextlib.contextmanager
def sigint_ignored_at_birth():
    """Start children inside this block: they are born ignoring ``SIGINT`` (the disposition
    survives ``exec``), so a Ctrl-C while a fresh interpreter is still importing prints no
    traceback from it; Ctrl-C stays the parent's to handle (it stops its workers)."""

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _pool_initializer(initializer, initargs) -> None:
    die_with_parent(ignore_sigint=True)
    if initializer is not None:
        initializer(*initargs)


def spawn_pool(max_workers: int, initializer=None, initargs=()) -> concurrent.futures.ProcessPoolExecutor:
    """A process pool of fresh interpreters whose workers die with this process."""
    return concurrent.futures.ProcessPoolExecutor(
        max_workers=max_workers, mp_context=multiprocessing.get_context("spawn"),
        initializer=_pool_initializer, initargs=(initializer, tuple(initargs)),
    )


def shutdown_pool(pool: concurrent.futures.ProcessPoolExecutor | None, kill: bool = False) -> None:
    """Shut ``pool`` down; with ``kill`` (after an error or an interrupt) its workers are killed
    first, so nothing waits on a task that will never finish."""
    if pool is None:
        return
    if kill:
        for proc in list(getattr(pool, "_processes", {}).values() or []):
            with contextlib.suppress(Exception):
                proc.kill()
    with contextlib.suppress(Exception):
        pool.shutdown(wait=not kill, cancel_futures=True)


class WorkerError(RuntimeError):
    """A worker process died, stopped answering, took too long, or (``kind="failed"``) raised:
    ``kind`` says which, ``remote`` holds what it raised (type name, message, traceback)."""

    def __init__(self, message: str, kind: str = "died", remote: tuple | None = None):
        super().__init__(message)
        self.kind, self.remote = kind, remote


HEARTBEAT_SECONDS = 0.5


def _dumps(obj) -> bytes:
    # plain pickle, by value: multiprocessing's own pickler would pass torch tensors as shared
    # file descriptors, which a worker that is not a multiprocessing child cannot open. These
    # bytes only ever travel between this process and its own worker (never a file).
    return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)


_loads = pickle.loads
_EXIT = _dumps(("exit", None, None))
WORKER_MODULE = "ials_zoo.runtime._worker"


def _heartbeat(fd: int) -> None:
    while True:
        try:
            os.write(fd, b".")
        except OSError:
            return
        time.sleep(HEARTBEAT_SECONDS)


_CONTEXT_PROVIDERS: list = []


def add_worker_context(provider) -> None:
    """Register ``provider() -> (install, payload) | None``: what every new :class:`Worker`
    must set up before it builds its object (``install(payload)`` runs in the worker, e.g.
    the domains registered at run time). ``install`` must be a module-level function."""
    if provider not in _CONTEXT_PROVIDERS:
        _CONTEXT_PROVIDERS.append(provider)


def _error(exc: BaseException) -> tuple:
    return "err", (type(exc).__name__, str(exc), traceback.format_exc())


def serve(read_fd: int, write_fd: int, beat_fd: int) -> None:
    """A :class:`Worker`'s process (``python -m ials_zoo.runtime._worker R W B``): take the parent's
    ``sys.path``, set up its contexts, build the object the init message names, then answer
    calls until told to exit (or the pipe closes). An exception goes back as ``(type name,
    message, traceback)`` and the loop goes on; with no object built, every call is refused."""

    die_with_parent(ignore_sigint=True)
    threading.Thread(target=_heartbeat, args=(beat_fd,), daemon=True).start()
    conn_r, conn_w = Connection(read_fd, writable=False), Connection(write_fd, readable=False)
    obj, built = None, False
    try:
        while True:
            try:
                data = conn_r.recv_bytes()
            except (EOFError, OSError):
                break
            try:
                kind, method, args = _loads(data)  # may import the factory's module: its errors go back
                if kind == "exit":
                    break
                if kind == "path":
                    sys.path[:] = list(method)
                    continue
                if kind == "init":
                    for install, payload in args[1]:
                        install(payload)
                    obj, built = method(*args[0]), True
                    result = None
                elif not built:
                    raise RuntimeError("this worker's object was never built (its construction failed)")
                else:
                    result = getattr(obj, method)(*args)
                reply = _dumps(("ok", result))
            except Exception as exc:
                reply = _dumps(_error(exc))
            try:
                conn_w.send_bytes(reply)
            except OSError:  # a broken pipe: the parent is gone (killed), so there is no one to tell
                break
    finally:
        close = getattr(obj, "close", None)
        if callable(close):
            with contextlib.suppress(Exception):
                close()


# what a worker raises for bad input comes back as bad input (ials_zoo.errors' family)
_BAD_INPUT_NAMES = ("BadInput", "BadInputType", "CommandError", "ResultError", "PolicyFileError")


class WorkerBadInput(WorkerError, BadInput):
    """Bad input found inside a worker (its message names it): printed like any bad input."""


def _start(fds: tuple[int, int, int], preload):
    """The process that serves on ``fds``: forked from the zygote of ``preload`` (Linux), or a
    fresh interpreter. A zygote that died since its last fork is replaced once."""
    if not preload or not zygotes.available():
        return fresh_interpreter(WORKER_MODULE, fds)
    for attempt in (0, 1):
        try:
            return zygotes.zygote_for(tuple(preload), SERVE_ENTRY).fork(fds)
        except zygotes.ZygoteError as exc:
            if exc.kind != "died" or attempt:
                raise WorkerError(f"could not start a worker: {exc}", kind=exc.kind) from None


SERVE_ENTRY = "ials_zoo.runtime.processes:serve"


class Worker:
    """``factory(*args)`` built in a fresh interpreter (``python -m ials_zoo.runtime._worker``: nothing
    of this process is inherited but ``sys.path`` and the registered contexts
    (:func:`add_worker_context`), no ``__main__`` guard needed, its console output dropped)
    that dies with this process, and called by method name over two dedicated pipes.
    ``preload`` (module names, or ``"module:function"`` to call): the interpreter is instead a
    fork of a :class:`ials_zoo.runtime.zygote.Zygote` that imported them once (Linux), which starts in
    milliseconds instead of the second a fresh interpreter needs to import them.

    Nothing waits forever on it, sending included. A :class:`WorkerError` naming the worker
    comes when it dies (``kind="died"``), is stopped by ``SIGSTOP`` or a debugger
    (``"stopped"``), sends no heartbeat for ``unresponsive_after`` seconds
    (``"unresponsive"``), takes longer than a call's ``timeout`` (``"timeout"``) -- after
    which the worker is killed -- or raises (``"failed"``; ``remote`` holds the exception's
    type name, message and traceback; the worker lives on; bad input comes back as
    :class:`WorkerBadInput`).

    ``call(method, *args)`` is one round trip; :meth:`send` then :meth:`receive` let several
    workers work at once (:func:`call_all`). A call's ``busy_for`` (seconds) allows work in
    compiled code that holds Python's lock, and so stops the heartbeat (SUMO loading a large
    network): while the worker's CPU time grows it counts as a heartbeat, up to ``busy_for``
    seconds; a worker that neither beats nor computes is still named after
    ``unresponsive_after``. ``name`` and ``detail`` make the messages,
    ``"<name> (pid <pid>, <detail>) died"``. The factory and the arguments travel pickled over
    our own pipe to our own child (never read from a file)."""

    def __init__(self, factory, args=(), name: str = "worker", detail: str = "",
                 unresponsive_after: float = 20.0, preload: tuple[str, ...] | None = None):

        self.name, self.detail = name, detail
        self.unresponsive_after = float(unresponsive_after)
        self._closed = False
        self._beat, self._ticks = time.monotonic(), None  # the last heartbeat; CPU time at the last look
        r_child, w_parent = os.pipe()  # parent -> child
        r_parent, w_child = os.pipe()  # child -> parent
        beat_r, beat_w = os.pipe()  # child -> parent heartbeats
        try:
            self.process = _start((r_child, w_child, beat_w), preload)
        except BaseException:
            for fd in (w_parent, r_parent, beat_r):
                os.close(fd)
            raise
        finally:
            for fd in (r_child, w_child, beat_w):
                os.close(fd)
        for fd in (beat_r, w_parent):
            os.set_blocking(fd, False)
        self._beat_fd, self._write_fd = beat_r, w_parent
        self._conn_r = Connection(r_parent, writable=False)
        contexts = [c for c in (provider() for provider in _CONTEXT_PROVIDERS) if c is not None]
        self._send(("path", list(sys.path), None))
        self._send(("init", factory, (tuple(args), contexts)))

    def started(self, timeout: float | None = 300.0) -> None:
        """Wait until the object is built (its constructor's error, if any, comes here)."""
        self.receive(timeout)

    @property
    def pid(self) -> int:
        return self.process.pid

    def _what(self) -> str:
        return f"{self.name} (pid {self.pid}{', ' + self.detail if self.detail else ''})"

    def _send(self, message, timeout: float | None = None) -> None:
        """Write one message as ``multiprocessing.connection`` frames it, a chunk at a time,
        watching the worker between chunks (a stopped worker never drains a full pipe)."""
        if self._closed:
            raise WorkerError(f"{self._what()} is closed", kind="died")
        data = _dumps(message)
        n = len(data)
        header = struct.pack("!i", n) if n <= 0x7FFFFFFF else struct.pack("!i", -1) + struct.pack("!Q", n)
        view = memoryview(header + data)
        start = last = time.monotonic()
        try:
            while view:
                _, writable, _ = select.select([], [self._write_fd], [], 0.1)
                if writable:
                    view = view[os.write(self._write_fd, view[:1 << 16]):]
                    continue
                last = self._check(start, last, timeout, answered=False)
        except (BrokenPipeError, OSError) as exc:
            # a worker killed between two calls: its end of the pipe is closed before any answer is awaited
            self._fail("died", f"{self._what()} died (its pipe closed: {exc}; exit code {self.process.poll()})")
        except WorkerError:
            raise
        except BaseException:
            self.close(kill=True)  # a message half-written: the pipe is out of step
            raise

    def _check(self, start: float, last: float, timeout: float | None, answered: bool,
               busy_for: float = 0.0) -> float:
        """Raise the WorkerError that applies now; returns the time of the last heartbeat (or,
        within ``busy_for`` seconds of the last true one, of the last growth of its CPU time)."""
        now = time.monotonic()
        if self._heard():
            last = self._beat = now
        elif busy_for and now - self._beat <= busy_for and self._computed():
            last = now
        if self.process.poll() is not None and not answered:
            self._fail("died", f"{self._what()} died (exit code {self.process.returncode})")
        if process_state(self.pid) in ("T", "t"):
            self._fail("stopped", f"{self._what()} is stopped (SIGSTOP or a debugger: process state T)")
        if now - last > self.unresponsive_after:
            self._fail("unresponsive", f"{self._what()} stopped answering (no heartbeat for {now - last:.0f} s)")
        if timeout is not None and now - start > timeout:
            self._fail("timeout", f"{self._what()} did not answer within {timeout:.0f} s")
        return last

    def send(self, method: str, *args) -> None:
        self._send(("call", method, args))

    def _computed(self) -> bool:
        """True when the worker's CPU time grew since the last look, or cannot be read (no
        ``/proc``: then the busy time is allowed whole; it is bounded all the same)."""
        ticks = process_cpu_ticks(self.pid)
        grew = ticks is None or self._ticks is None or ticks > self._ticks
        self._ticks = ticks
        return grew

    def _heard(self) -> bool:
        """Drain the heartbeat pipe; True when the worker beat since the last look."""
        heard = False
        while True:
            try:
                chunk = os.read(self._beat_fd, 4096)
            except OSError:  # BlockingIOError: nothing more
                return heard
            if not chunk:
                return heard
            heard = True

    def receive(self, timeout: float | None = None, busy_for: float = 0.0):
        """The answer to the last :meth:`send` (see the class docstring for the errors)."""
        start = last = self._beat = time.monotonic()
        self._ticks = process_cpu_ticks(self.pid) if busy_for else None
        try:
            while not self._conn_r.poll(0.1):
                last = self._check(start, last, timeout, answered=self._conn_r.poll(0), busy_for=busy_for)
            status, payload = _loads(self._conn_r.recv_bytes())
        except (EOFError, OSError) as exc:
            self._fail("died", f"{self._what()} died (exit code {self.process.poll()}; {exc})")
        except WorkerError:
            raise
        except BaseException:
            # e.g. Ctrl-C while waiting: the answer would come out of turn later
            self.close(kill=True)
            raise
        if status == "err":
            type_name, message, trace = payload
            if type_name in _BAD_INPUT_NAMES:
                raise WorkerBadInput(message, kind="failed", remote=(type_name, message, trace))
            raise WorkerError(f"{self._what()} failed: {type_name}: {message}\n{trace}", kind="failed",
                              remote=(type_name, message, trace))
        return payload

    def call(self, method: str, *args, timeout: float | None = None, busy_for: float = 0.0):
        self.send(method, *args)
        return self.receive(timeout, busy_for)

    def _fail(self, kind: str, message: str):
        self.close(kill=True)
        raise WorkerError(message, kind=kind)

    def close(self, kill: bool = False) -> None:
        """Ask the worker to close its object and exit (``kill``: at once); idempotent."""
        if self._closed:
            return
        self._closed = True
        if not kill and self.process.poll() is None:
            with contextlib.suppress(OSError, BrokenPipeError):
                os.write(self._write_fd, struct.pack("!i", len(_EXIT)) + _EXIT)  # small: never blocks
            with contextlib.suppress(Exception):
                self.process.wait(timeout=10)
        if self.process.poll() is None:
            self.process.kill()
        with contextlib.suppress(Exception):
            self.process.wait(timeout=5)
        if isinstance(self.process, zygotes.ForkedProcess):
            self.process.release()
        with contextlib.suppress(OSError):
            self._conn_r.close()
        for fd in (self._write_fd, self._beat_fd):
            with contextlib.suppress(OSError):
                os.close(fd)

    def __del__(self):
        with contextlib.suppress(Exception):
            self.close(kill=True)


def call_all(workers: list[Worker], method: str, args: list | None = None, timeout: float | None = None) -> list:
    """``method`` on every worker at once (``args[i]``: worker i's argument tuple); the
    answers in order. On any error every worker is killed and the error raised."""
    args = args or [()] * len(workers)
    try:
        for w, a in zip(workers, args):
            w.send(method, *a)
        return [w.receive(timeout) for w in workers]
    except BaseException:
        for w in workers:
            w.close(kill=True)
        raise


def start_all(workers: list[Worker], timeout: float | None = 300.0) -> None:
    """Wait until every worker built its object; on any error every worker is killed."""
    try:
        for w in workers:
            w.started(timeout)
    except BaseException:
        for w in workers:
            w.close(kill=True)
        raise


def _proc_table() -> dict[int, tuple[int, str]]:
    """``{pid: (parent pid, start time)}`` of every process, from ``/proc``."""
    table = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            table[int(entry)] = (int(fields[1]), fields[19])
        except (OSError, IndexError, ValueError):
            continue
    return table


def _descendants(root: int, table: dict) -> dict[int, str]:
    children: dict[int, list[int]] = {}
    for pid, (ppid, _) in table.items():
        children.setdefault(ppid, []).append(pid)
    out, todo = {}, list(children.get(root, []))
    while todo:
        pid = todo.pop()
        out[pid] = table[pid][1]
        todo += children.get(pid, [])
    return out


def _reaper(parent: int, fd: int) -> None:
    """The watchdog of :func:`reap_descendants_when_gone`: every second, remember the parent's
    descendants; when the parent's pipe closes (it died or exited), kill those still alive."""

    me, known = os.getpid(), {}
    while True:
        ready, _, _ = select.select([fd], [], [], 1.0)
        if ready and not os.read(fd, 1):
            break
        known.update({pid: start for pid, start in _descendants(parent, _proc_table()).items() if pid != me})
    table = _proc_table()
    for pid, start in known.items():
        if pid in table and table[pid][1] == start:  # the same process, not a reused pid
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)


def reap_descendants_when_gone() -> None:
    """Start a watchdog that kills this process's descendants once this process is gone, however
    it goes (``kill -9`` included), for children we do not start ourselves and so cannot ask
    to die with us (a local Ray cluster's raylet, GCS and agents). Linux only; at most one per
    process."""

    global _REAPER
    if _REAPER is not None or not sys.platform.startswith("linux"):
        return
    r, w = os.pipe()
    with sigint_ignored_at_birth():
        _REAPER = subprocess.Popen([sys.executable, "-c", f"from ials_zoo.runtime.processes import _reaper; _reaper({os.getpid()}, {r})"],
                                   pass_fds=(r,), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                   start_new_session=True)
    os.close(r)
    _REAPER_PIPE.append(w)  # held open for this process's life; its closing is the signal


_REAPER = None
_REAPER_PIPE: list[int] = []


__all__ = ["Worker", "WorkerBadInput", "WorkerError", "add_worker_context", "call_all", "die_with_parent", "keep_freed_memory", "process_state", "reap_descendants_when_gone",
           "shutdown_pool", "sigint_ignored_at_birth", "spawn_pool", "start_all"]
