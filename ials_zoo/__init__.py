"""ials_zoo: benchmark suite for deep multi-agent RL in large networked systems.

Global simulators (PettingZoo ``ParallelEnv``)::

    from ials_zoo import warehouse_v0, traffic_grid_v0
    env = warehouse_v0.parallel_env(learners=["robot_20"])

Influence-augmented local simulators (Gymnasium ``Env``)::

    import ials_zoo
    env = ials_zoo.make_ials("warehouse_v0", "robot_20")

or, through Gymnasium (registered on ``import ials_zoo``)::

    env = gymnasium.make("ials_zoo/IALS-warehouse_v0", agent="robot_20")
"""

__version__ = "0.1.0"


def make_ials(*args, **kwargs):
    """Build the influence-augmented local simulator of one agent (see ``ials_zoo.influence``)."""
    from ials_zoo.influence.ials import make_ials as _make_ials

    return _make_ials(*args, **kwargs)


def _register_gymnasium() -> None:
    """Register ``ials_zoo/IALS-<env_id>`` for every domain (cheap: nothing is imported)."""
    import gymnasium

    from ials_zoo.core.domains import domain_ids

    for env_id in domain_ids():
        gym_id = f"ials_zoo/IALS-{env_id}"
        if gym_id not in gymnasium.registry:
            gymnasium.register(
                id=gym_id,
                entry_point="ials_zoo.influence.ials:gymnasium_entry_point",
                kwargs={"env_id": env_id},
            )


_register_gymnasium()

__all__ = ["__version__", "make_ials"]
