"""ials_zoo: benchmark suite for deep multi-agent RL in large networked systems.

Global simulators (PettingZoo ``ParallelEnv``)::

    from ials_zoo import warehouse_v0, traffic_grid_v0
    env = warehouse_v0.parallel_env(learners=["robot_20"])

Influence-augmented local simulators: one agent (Gymnasium ``Env``), or every agent at once
(PettingZoo ``ParallelEnv``, the multi-agent IALS of DIALS)::

    import ials_zoo
    env = ials_zoo.make_ials("warehouse_v0", "robot_20")
    env = ials_zoo.make_ials_parallel_env("traffic_grid_v0")

or, through Gymnasium (registered on ``import ials_zoo``)::

    env = gymnasium.make("ials_zoo/IALS-warehouse_v0", agent="robot_20")

Your own domain: build an :class:`ials_zoo.core.Domain` and :func:`register_domain` it (or
declare it in the ``ials_zoo.domains`` entry point group).
"""

from ials_zoo._version import __version__
from ials_zoo.core.domains import Domain, domain_ids, get_domain, ials_domain_ids, register_domain
from ials_zoo.core.gym_ids import register_ials


def make_ials(*args, **kwargs):
    """Build the influence-augmented local simulator of one agent (see ``ials_zoo.influence``)."""
    from ials_zoo.influence.ials import make_ials as _make_ials  # lazy: SB3/torch

    return _make_ials(*args, **kwargs)


def make_ials_parallel_env(*args, **kwargs):
    """Build the multi-agent IALS, a PettingZoo ``ParallelEnv`` (see ``ials_zoo.influence.multi``)."""
    from ials_zoo.influence.multi import make_ials_parallel_env as _make  # lazy: SB3/torch

    return _make(*args, **kwargs)


for _env_id in ials_domain_ids():  # every IALS domain's IALS as a Gymnasium id (ials_zoo.core.gym_ids)
    register_ials(_env_id)
del _env_id

__all__ = [
    "Domain",
    "__version__",
    "domain_ids",
    "get_domain",
    "make_ials",
    "make_ials_parallel_env",
    "register_domain",
]
