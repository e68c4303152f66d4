"""Where DIALS's shards run: this process, worker processes, or Ray actors.

Every backend runs one :class:`~ials_zoo.dials.shard.AgentShard` per worker and answers
``call(method, args)`` -- the method run on every shard at once, the results in shard order:

* :class:`InProcessBackend` (``workers=0``): the shards in this process, one after the other;
* :class:`ProcessBackend` (default): one fresh interpreter per shard (no extra dependency),
  dying with this process; a worker that dies, is stopped, or stops sending its heartbeat for
  :data:`UNRESPONSIVE_SECONDS` raises :class:`~ials_zoo.runtime.processes.WorkerError` naming it;
* :class:`RayBackend`: one Ray actor per shard (:class:`~ials_zoo.runtime.ray_actors.RayActors`: a
  local Ray of the run's own or an existing cluster, with our worker rules).
"""

from __future__ import annotations

from ials_zoo.dials.shard import AgentShard, ShardSpec
from ials_zoo.errors import BadInput
from ials_zoo.runtime.processes import Worker, call_all, start_all
from ials_zoo.runtime.ray_actors import RayActors, check_ray_address

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
    """One worker process per shard (module docstring): a :class:`~ials_zoo.runtime.processes.Worker`
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


class RayBackend(RayActors):
    """One Ray actor per shard (module docstring; :class:`~ials_zoo.runtime.ray_actors.RayActors`)."""

    name = "ray"

    def __init__(self, specs: list[ShardSpec], address: str | None = None):
        super().__init__(AgentShard, [(spec,) for spec in specs], address, what="DIALS Ray actor")


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
