"""Where DIALS's shards run: this process, worker processes, or Ray actors.

Every backend runs one :class:`~ials_zoo.dials.shard.AgentShard` per worker and answers
``call(method, args)`` -- the method run on every shard at once, the results in shard order:

* :class:`InProcessBackend` (``workers=0``): the shards in this process, one after the other;
* :class:`ProcessBackend` (default): one fresh interpreter per shard (no extra dependency),
  dying with this process; a worker that dies, is stopped, or stops sending its heartbeat for
  :data:`UNRESPONSIVE_SECONDS` raises :class:`~ials_zoo.processes.WorkerError` naming it;
* :class:`RayBackend`: one Ray actor per shard, on a new local Ray of its own (it dies with the
  run, even after kill -9; never a cluster already running here) or an existing cluster
  (``address``: the run's actors die with it, the cluster is left alone; an address where
  nothing answers is refused within seconds, before Ray would wait for it). Needs
  ``pip install "ials-zoo[ray]"``. Ray 2.59+ turns token authentication on for ``ray start
  --head`` when ``~/.ray/auth_token`` exists, and a joining driver sends no token: start such a
  head with ``RAY_AUTH_MODE=disabled`` or join it with ``RAY_AUTH_MODE=token``.
"""

from __future__ import annotations

import socket
from urllib.parse import urlparse

from ials_zoo.dials.shard import AgentShard, ShardSpec
from ials_zoo.errors import BadInput
from ials_zoo.processes import (
    Worker,
    WorkerError,
    call_all,
    process_state,
    reap_descendants_when_gone,
    start_all,
)

BACKENDS = ("process", "ray")
UNRESPONSIVE_SECONDS = 20.0


class InProcessBackend:
    """Every shard in this process (no parallelism; for tests and debugging)."""

    name = "inprocess"

    def __init__(self, specs: list[ShardSpec]):
        self.shards = []
        try:
            for spec in specs:
                self.shards.append(AgentShard(spec))
        except BaseException:
            self.close()
            raise

    def call(self, method: str, args: list | None = None) -> list:
        args = args or [()] * len(self.shards)
        return [getattr(s, method)(*a) for s, a in zip(self.shards, args)]

    def close(self):
        for s in self.shards:
            s.close()
        self.shards = []


class ProcessBackend:
    """One worker process per shard (module docstring): a :class:`~ials_zoo.processes.Worker`
    holding an :class:`AgentShard`."""

    name = "process"

    def __init__(self, specs: list[ShardSpec], unresponsive_after: float = UNRESPONSIVE_SECONDS):
        self.workers = []
        try:
            for i, spec in enumerate(specs):
                self.workers.append(Worker(AgentShard, (spec,), name=f"DIALS worker {i}",
                                           detail=f"agents {spec.agents[0]}..{spec.agents[-1]}",
                                           unresponsive_after=unresponsive_after))
            start_all(self.workers)  # each worker built its shard
        except BaseException:
            self.close(kill=True)
            raise

    def call(self, method: str, args: list | None = None) -> list:
        return call_all(self.workers, method, args)

    def close(self, kill: bool = False):
        for w in self.workers:
            w.close(kill=kill)
        self.workers = []


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


class RayBackend:
    """One Ray actor per shard (module docstring)."""

    name = "ray"

    def __init__(self, specs: list[ShardSpec], address: str | None = None):
        try:
            import ray
        except ImportError:
            raise BadInput('the Ray backend needs Ray: pip install "ials-zoo[ray]"') from None
        if address is not None:
            check_ray_address(address)
        self.ray = ray
        self._own = not ray.is_initialized()
        if self._own:
            kwargs = {"include_dashboard": False, "log_to_driver": False}
            if address is None:
                kwargs["num_cpus"] = max(len(specs), 1)
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
        actor = ray.remote(num_cpus=1)(AgentShard)
        try:
            self.actors = [actor.remote(spec) for spec in specs]
            ray.get([a.__ray_ready__.remote() for a in self.actors])
            here = socket.gethostname()
            # an actor on another machine cannot be watched from here (its process state)
            self.pids = [pid if host == here else None for pid, host in ray.get([a.where.remote() for a in self.actors])]
        except BaseException:
            self.close()
            raise

    def call(self, method: str, args: list | None = None) -> list:
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
            raise WorkerError(f"a DIALS Ray actor failed: {exc}") from None
        except BaseException:
            self.close()
            raise

    def _check_stopped(self) -> None:
        """A WorkerError naming an actor whose process (on this machine) is stopped."""
        for i, pid in enumerate(self.pids):
            if pid is not None and process_state(pid) in ("T", "t"):
                raise WorkerError(f"DIALS Ray actor {i} (pid {pid}) is stopped (SIGSTOP or a debugger: process "
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


def make_backend(name: str, specs: list[ShardSpec], address: str | None = None):
    """The backend ``name`` (``process`` or ``ray``) over ``specs``; no spec: in this process."""
    if name == "ray":
        return RayBackend(specs, address)
    if address is not None:
        raise BadInput("--ray-address needs --backend ray")
    if name != "process":
        raise BadInput(f"unknown backend {name!r}; expected one of {BACKENDS}")
    return ProcessBackend(specs)


__all__ = ["BACKENDS", "InProcessBackend", "ProcessBackend", "RayBackend", "check_ray_address", "make_backend"]
