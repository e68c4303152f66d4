"""DIALS's distributed training: agent shards and the backends that run them.

* :mod:`~ials_zoo.dials.shard` -- :class:`AgentShard`, some agents each learning on its own
  IALS, in one worker;
* :mod:`~ials_zoo.dials.backends` -- where the shards run: this process, worker processes
  (default) or Ray actors.

The training loop (AIP refreshes, GS evaluations, checkpoints) is the baseline
:mod:`ials_zoo.baselines.dials`.
"""
