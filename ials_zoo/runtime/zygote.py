"""Zygotes: processes that import a list of modules once, then fork workers on request.

A fresh interpreter spends most of a second importing libsumo, numpy and the zoo before it can
run anything; a fork of a process that has imported them, and done nothing else (no simulation
started, nothing of the parent's state), is ready in milliseconds. :class:`Zygote` is the parent's
handle on one such process (``python -m ials_zoo.runtime._zygote``), :class:`ForkedProcess` its handle on
a worker the zygote forked, with the part of ``subprocess.Popen`` that
:class:`ials_zoo.runtime.processes.Worker` uses.

The rules every child process of ours keeps, kept here as follows:

* **Dies with its parent.** The zygote exits when the parent's socket closes, however the parent
  dies (the kernel closes it); its workers get ``SIGKILL`` when the zygote dies (they set the
  death signal themselves: :func:`ials_zoo.runtime.processes.serve`). The zygote sets no death signal of
  its own: that signal follows the *thread* that started it, and a zygote shared by all the
  threads of the parent must not die with one of them.
* **Nothing waits forever.** Every request waits for its answer at most
  :attr:`Zygote.START_SECONDS` while the zygote imports, then :attr:`Zygote.ANSWER_SECONDS`; a
  stopped zygote (``SIGSTOP``) is named at once. A request cut short (Ctrl-C, a timeout) leaves
  its answer behind: answers carry the request's number, so a late one is skipped, never taken
  for another's.
* **No zombies, no pid confusion.** The zygote reaps every child that exits (at least once a
  second) and keeps its exit code until asked. The parent watches a worker through a pidfd, which
  names that process and no later one with its pid.
* **A fork of the parent** (``os.fork``) starts its own zygote when it needs one, and treats the
  parent's workers as not its own (never signals them).

Messages are packets (``SOCK_SEQPACKET``: one request or answer each, never split or merged); the
zygote is our own child and the bytes never come from a file.
"""

from __future__ import annotations

import atexit
import contextlib
import importlib
import itertools
import json
import os
import select
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
import traceback

from ials_zoo.runtime.children import fresh_interpreter, process_state

ZYGOTE_MODULE = "ials_zoo.runtime._zygote"
_FORK, _REAP = b"F", b"R"
_ANSWER = struct.Struct("!qq")  # request number, value
_UNKNOWN = -(1 << 40)  # an exit code the zygote does not know (yet)
_FAILED = -(1 << 41)  # the zygote could not fork
_MAX_CODES = 4096


class ZygoteError(RuntimeError):
    """The zygote died, stopped, did not answer in time, or could not fork (``kind``)."""

    def __init__(self, message: str, kind: str = "died"):
        super().__init__(message)
        self.kind = kind


# ----------------------------------------------------------------------------- the zygote's side


def _preload(entries) -> None:
    for entry in entries:
        module, _, function = entry.partition(":")
        try:  # a failed preload fails again, with its message, in the worker that needs it
            loaded = importlib.import_module(module)
            if function:
                getattr(loaded, function)()
        except BaseException:  # SystemExit in an import must not end the zygote
            continue


def _collect(codes: dict) -> None:
    """Reap every child that has exited and keep its exit code (the oldest forgotten first)."""
    while True:
        try:
            pid, status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return
        codes[pid] = os.waitstatus_to_exitcode(status)
        while len(codes) > _MAX_CODES:
            codes.pop(next(iter(codes)))


def _child(sock, fds, cwd: str, entry: str) -> None:
    """In the forked worker: become the worker (``entry(*fds)``), never return to the loop."""
    code = 0
    try:
        sock.close()
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        with contextlib.suppress(OSError):
            os.chdir(cwd)
        module, _, name = entry.partition(":")
        getattr(importlib.import_module(module), name)(*fds)
    except (BrokenPipeError, ConnectionResetError):  # its parent was killed: nobody to tell, leave quietly
        code = 1
    except BaseException:  # the worker's last words go to stderr; its exit code says it failed
        traceback.print_exc()
        code = 1
    finally:
        os._exit(code)


def _answer(sock, number: int, value: int) -> None:
    with contextlib.suppress(OSError):
        sock.send(_ANSWER.pack(number, value))


def zygote_main(sock_fd: int, setup: str) -> None:
    """The zygote's process: ``SETUP`` is JSON ``[sys.path, preload, entry]``; then one request
    at a time until the parent's socket closes (module docstring)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    path, preload, entry = json.loads(setup)
    sys.path[:] = path
    _preload(preload)
    sock, codes = socket.socket(fileno=sock_fd), {}
    while True:
        ready, _, _ = select.select([sock], [], [], 1.0)
        _collect(codes)
        if not ready:
            continue
        try:
            data, fds, _, _ = socket.recv_fds(sock, 1 << 16, 3)
        except OSError:
            return
        if not data:
            return  # the parent is gone: the workers die with this process
        kind, number = data[:1], struct.unpack("!q", data[1:9])[0]
        if kind == _FORK and len(fds) == 3:
            try:
                pid = os.fork()
            except OSError:
                pid = _FAILED
            if pid == 0:
                _child(sock, fds, data[9:].decode("utf-8", "surrogateescape"), entry)
            for fd in fds:
                os.close(fd)
            _answer(sock, number, pid)
        elif kind == _REAP:
            _collect(codes)
            _answer(sock, number, codes.pop(struct.unpack("!q", data[9:17])[0], _UNKNOWN))
        else:
            for fd in fds:
                os.close(fd)


# ----------------------------------------------------------------------------- the parent's side


class ForkedProcess:
    """A worker forked by a :class:`Zygote` (``pid``, ``poll``, ``returncode``, ``wait``,
    ``kill``, as ``subprocess.Popen`` has them; an exit code the zygote no longer knows is -1)."""

    def __init__(self, zygote: Zygote, pid: int):
        self.pid, self.returncode, self._zygote, self._owner = pid, None, zygote, os.getpid()
        self._pidfd = os.pidfd_open(pid)

    def _exited(self, timeout: float = 0.0) -> bool:
        poller = select.poll()  # not select.select: a pidfd may be numbered past 1024
        poller.register(self._pidfd, select.POLLIN)
        return bool(poller.poll(int(timeout * 1000)))

    def poll(self) -> int | None:
        if self.returncode is not None:
            return self.returncode
        if os.getpid() != self._owner:
            return 0  # a fork of the parent: not its worker (as Popen says of another's child)
        if self._pidfd is None or not self._exited():
            return None
        code = self._zygote.reap(self.pid)
        if code is not None:
            self.returncode = code
        return -1 if code is None else code  # the lock was busy: exited, code asked for later

    def wait(self, timeout: float | None = None) -> int:
        if self.poll() is None and self._pidfd is not None and os.getpid() == self._owner:
            self._exited(3600.0 if timeout is None else timeout)
        code = self.poll()
        if code is None:
            raise subprocess.TimeoutExpired(f"pid {self.pid}", timeout)
        return code

    def kill(self) -> None:
        if self._pidfd is not None and os.getpid() == self._owner and self.poll() is None:
            with contextlib.suppress(OSError):
                signal.pidfd_send_signal(self._pidfd, signal.SIGKILL)

    def release(self) -> None:
        """Close the pidfd (after :meth:`wait`); the process is not watched any more."""
        if self._pidfd is not None:
            with contextlib.suppress(OSError):
                os.close(self._pidfd)
            self._pidfd = None


class Zygote:
    """The parent's handle on one zygote (module docstring); one per preload list and
    environment (:func:`zygote_for`)."""

    START_SECONDS = 300.0  # the first answer waits for the imports
    ANSWER_SECONDS = 10.0  # a fork or a reap, after that

    def __init__(self, preload: tuple[str, ...], entry: str):
        self.preload, self.owner, self.broken = tuple(preload), os.getpid(), False
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            setup = json.dumps([list(sys.path), list(self.preload), entry])
            self.process = fresh_interpreter(ZYGOTE_MODULE, (theirs.fileno(),), (setup,))
        except BaseException:
            ours.close()
            raise
        finally:
            theirs.close()
        self._sock, self._lock, self._numbers, self._answered = ours, threading.Lock(), itertools.count(1), False

    def alive(self) -> bool:
        return not self.broken and self.process.poll() is None

    def _fail(self, kind: str, message: str):
        self.broken = True  # zygote_for starts another
        raise ZygoteError(f"the zygote (pid {self.process.pid}) {message}", kind)

    def _receive(self, number: int) -> int:
        start, limit = time.monotonic(), self.ANSWER_SECONDS if self._answered else self.START_SECONDS
        self._sock.settimeout(0.2)
        while True:
            try:
                data = self._sock.recv(_ANSWER.size)
            except TimeoutError:
                data = None
            except OSError:
                data = b""
            if data == b"" or self.process.poll() is not None:
                self._fail("died", f"died (exit code {self.process.poll()})")
            if data and _ANSWER.unpack(data)[0] == number:
                self._answered = True
                return _ANSWER.unpack(data)[1]
            if process_state(self.process.pid) in ("T", "t"):
                self._fail("stopped", "is stopped (SIGSTOP or a debugger)")
            if time.monotonic() - start > limit:
                self._fail("timeout", f"did not answer within {limit:.0f} s")

    def _ask(self, kind: bytes, payload: bytes = b"", fds=(), blocking: bool = True) -> int | None:
        if not self._lock.acquire(blocking=blocking, timeout=-1 if not blocking else self.START_SECONDS):
            return None
        try:
            number = next(self._numbers)
            try:
                socket.send_fds(self._sock, [kind + struct.pack("!q", number) + payload], list(fds))
            except OSError as exc:
                self._fail("died", f"is gone ({exc})")
            return self._receive(number)
        finally:
            self._lock.release()

    def fork(self, fds: tuple[int, int, int]) -> ForkedProcess:
        """A worker serving on ``fds`` (the entry's read, write and heartbeat pipes), started in
        this process's current folder."""
        pid = self._ask(_FORK, os.getcwd().encode("utf-8", "surrogateescape"), fds)
        if pid is None or pid <= 0:
            raise ZygoteError(f"the zygote (pid {self.process.pid}) could not fork a worker", "died")
        return ForkedProcess(self, pid)

    def reap(self, pid: int) -> int | None:
        """The exit code of ``pid``, a child of this zygote that has exited: -1 where no longer
        known, None when another thread is asking the zygote now (ask again later)."""
        try:
            code = self._ask(_REAP, struct.pack("!q", pid), blocking=False)
        except ZygoteError:
            return -1  # the zygote is gone: its children were reparented and reaped elsewhere
        if code is None:
            return None
        return code if code > _UNKNOWN else -1

    def close(self) -> None:
        if os.getpid() != self.owner:
            return  # a fork of the parent does not end the parent's zygote
        with contextlib.suppress(OSError):
            self._sock.close()
        with contextlib.suppress(Exception):
            self.process.wait(timeout=5)
        if self.process.poll() is None:
            self.process.kill()
            with contextlib.suppress(Exception):
                self.process.wait(timeout=5)


_zygotes: dict[tuple, Zygote] = {}
_zygotes_lock = threading.Lock()


def _forget_after_fork() -> None:
    global _zygotes_lock
    _zygotes.clear()  # the parent's zygotes are the parent's: this process starts its own
    _zygotes_lock = threading.Lock()


def available() -> bool:
    """Whether workers can be forked from zygotes here (Linux with pidfds, 5.3 and later)."""
    return hasattr(os, "pidfd_open") and hasattr(signal, "pidfd_send_signal") and hasattr(os, "fork")


def zygote_for(preload: tuple[str, ...], entry: str) -> Zygote:
    """The live zygote of ``preload`` (and of this environment: a changed ``os.environ`` gets
    its own), started at first use; ``entry`` (``"module:function"``) is what a fork runs."""
    key = (tuple(preload), entry, hash(frozenset(os.environ.items())))
    with _zygotes_lock:
        zygote = _zygotes.get(key)
        if zygote is None or not zygote.alive():
            if zygote is not None:
                zygote.close()
            zygote = _zygotes[key] = Zygote(tuple(preload), entry)
        return zygote


def close_zygotes() -> None:
    """End every zygote of this process (their workers die with them)."""
    for zygote in list(_zygotes.values()):
        zygote.close()
    _zygotes.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_after_fork)
atexit.register(close_zygotes)

__all__ = ["ForkedProcess", "Zygote", "ZygoteError", "available", "close_zygotes", "zygote_for", "zygote_main"]
