"""The zoo's runtime: every process it starts, and what each promises.

One concern lives here: processes that never outlive their parent and never make it wait
forever. Every child keeps three rules: it **dies with its parent** however the parent dies
(Ctrl-C, ``SIGTERM``, ``kill -9``); **nothing waits forever** (every call has a timeout, every
pool shuts down without waiting on a worker that no longer answers); and **a stuck worker is
named within seconds** (a heartbeat, read beside the CPU time it spends, so a long SUMO load is
not taken for a hang).

* :mod:`~ials_zoo.runtime.processes`: :class:`~ials_zoo.runtime.processes.Worker`, the one
  protocol for a long-lived worker (an object built in a fresh interpreter and called by method
  name, with a heartbeat, a death and stop signal and a timeout); :func:`spawn_pool` /
  :func:`shutdown_pool` for pools of short tasks; :func:`die_with_parent`.
* :mod:`~ials_zoo.runtime.zygote`: processes that import libsumo, numpy and the zoo once, then
  fork ready workers in milliseconds (Linux).
* :mod:`~ials_zoo.runtime.children`: starting a fresh interpreter and reading a process's state
  and CPU time from ``/proc``, shared by the two above.
* :mod:`~ials_zoo.runtime.ray_actors`: the same rules for Ray actors (a Ray of the run's own,
  or a cluster's address checked within seconds). Needs the ``ray`` extra.
* ``_worker`` and ``_zygote``: the entry points (``python -m ials_zoo.runtime._worker``,
  ``python -m ials_zoo.runtime._zygote``) of a worker's and a zygote's interpreter.

Nothing here names a domain: the callers (SUMO leases, DIALS shards, GS copies, SB3's vector
envs, collection and evaluation pools, studies) bring the objects to run.
"""
