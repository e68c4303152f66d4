"""Objects as Ray actors, one per share of a run's work, with the rules our worker processes
keep: on a new local Ray of the run's own (it dies with the run, even after kill -9; never a
cluster already running here) or an existing cluster (``address``: the run's actors die with
it, the cluster is left alone; an address where nothing answers is refused within seconds,
before Ray would wait for it); a call never waits forever, and an actor on this machine that is
stopped is named within seconds. Needs ``pip install "ials-zoo[ray]"``. Ray 2.59+ turns token
authentication on for ``ray start --head`` when ``~/.ray/auth_token`` exists, and a joining
driver sends no token: start such a head with ``RAY_AUTH_MODE=disabled`` or join it with
``RAY_AUTH_MODE=token``.

Used by DIALS's agent shards (:mod:`ials_zoo.dials.backends`) and by the copies of a
multi-agent simulator (:class:`~ials_zoo.learners.gs_vec.GSVecEnv`).
"""

from __future__ import annotations

import os
import socket
from urllib.parse import urlparse

from ials_zoo.errors import BadInput
from ials_zoo.runtime.processes import WorkerError, process_state, reap_descendants_when_gone


def check_ray_address(address: str, timeout: float = 5.0) -> None:
    """A ValueError unless something accepts TCP connections at ``address`` (``host:port``
    or ``ray://host:port``) within ``timeout`` seconds (Ray itself would wait for minutes)."""
    if address == "auto":
        return
    parsed = urlparse(address if "://" in address else f"tcp://{address}")
    if not parsed.hostname or not parsed.port:
        raise BadInput(f"--ray-address {address!r}: expected host:port or ray://host:port")
    try:
        socket.create_connection((parsed.hostname, parsed.port), timeout=timeout).close()
    except OSError as exc:
        raise BadInput(f"--ray-address {address!r}: nothing answers there ({exc}); start the cluster "
                         "with `ray start --head` or leave --ray-address out for a local Ray") from None


def _init_ray(ray, actors: int, address: str | None) -> bool:
    """Start or join Ray unless this process already did; whether we started it."""
    if ray.is_initialized():
        return False
    kwargs = {"include_dashboard": False, "log_to_driver": False}
    if address is None:
        kwargs["num_cpus"] = max(actors, 1)
        # the local Ray we start (raylet, GCS, agents) dies with us, even after kill -9;
        # a cluster we only connect to is left alone
        reap_descendants_when_gone()
    try:
        # "local": a Ray of our own, never a cluster that ray.init() would otherwise find
        # on this machine (or a dead one its address file still names)
        ray.init(address=address or "local", **kwargs)
    except ConnectionError as exc:  # something answers there, but not a Ray we may join
        raise BadInput(f"--ray-address {address!r}: Ray could not connect ({exc}); a head that runs token "
                       "authentication (Ray 2.59+ turns it on where ~/.ray/auth_token exists) needs "
                       "RAY_AUTH_MODE=token here") from None
    return True


class RayActors:
    """``cls(*args)`` as one Ray actor (one CPU) per entry of ``arguments`` (module docstring).
    ``cls`` needs ``where()`` (its process id and host) and ``close()``. ``what`` names the
    actors in errors."""

    def __init__(self, cls, arguments: list[tuple], address: str | None = None, what: str = "Ray actor"):
        try:
            import ray
        except ImportError:
            raise BadInput('the Ray backend needs Ray: pip install "ials-zoo[ray]"') from None
        if address is not None:
            check_ray_address(address)
        self.ray, self.what = ray, what
        self._own = _init_ray(ray, len(arguments), address)
        actor = ray.remote(num_cpus=1)(cls)
        try:
            self.actors = [actor.remote(*args) for args in arguments]
            ray.get([a.__ray_ready__.remote() for a in self.actors])
            here = socket.gethostname()
            # an actor on another machine cannot be watched from here (its process state)
            self.pids = [pid if host == here else None for pid, host in ray.get([a.where.remote() for a in self.actors])]
        except BaseException:
            self.close()
            raise

    def call(self, method: str, args: list | None = None) -> list:
        """``method`` on every actor at once (``args[i]``: actor i's argument tuple); the
        answers in order. On any error every actor is closed and the error raised."""
        args = args or [()] * len(self.actors)
        refs = [getattr(a, method).remote(*x) for a, x in zip(self.actors, args)]
        try:
            pending = list(refs)
            while pending:  # never wait forever: a stopped local actor is named in seconds
                _, pending = self.ray.wait(pending, num_returns=len(pending), timeout=0.5)
                if pending:
                    self._check_stopped()
            return self.ray.get(refs)
        except self.ray.exceptions.RayError as exc:
            self.close()
            raise WorkerError(f"a {self.what} failed: {exc}") from None
        except BaseException:
            self.close()
            raise

    def _check_stopped(self) -> None:
        """A WorkerError naming an actor whose process (on this machine) is stopped."""
        for i, pid in enumerate(self.pids):
            if pid is not None and process_state(pid) in ("T", "t"):
                raise WorkerError(f"{self.what} {i} (pid {pid}) is stopped (SIGSTOP or a debugger: process "
                                  "state T)")

    def close(self):
        for a in getattr(self, "actors", []):
            try:
                self.ray.get(a.close.remote(), timeout=10)
            except Exception:
                pass
            try:
                self.ray.kill(a)
            except Exception:
                pass
        self.actors = []
        if getattr(self, "_own", False) and self.ray.is_initialized():
            self.ray.shutdown()


def where() -> tuple[int, str]:
    """This process's id and host (what :class:`RayActors` needs of an actor to watch it)."""

    return os.getpid(), socket.gethostname()


__all__ = ["RayActors", "check_ray_address", "where"]
