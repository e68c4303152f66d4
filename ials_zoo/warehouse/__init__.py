"""Warehouse commissioning (``warehouse_v0``, SPEC §1): 36 robots fetch items from shelves.

* :mod:`ials_zoo.warehouse.regions` -- floor/region layout, item-bit order, influence sources,
  movement and shortest-path tables, the item process shared by the GS and the LS.
* :mod:`ials_zoo.warehouse.env` -- the global simulator, :class:`WarehouseEnv` (PettingZoo).
* :mod:`ials_zoo.warehouse.local` -- the local simulator, :class:`WarehouseLocalSimulator`.
* :mod:`ials_zoo.warehouse.render` -- images, text view, episode GIFs.
"""

from ials_zoo.core.domains import Domain
from ials_zoo.warehouse.env import WarehouseEnv, env, parallel_env, raw_env
from ials_zoo.warehouse.local import WarehouseLocalSimulator, local_simulator
from ials_zoo.warehouse.regions import possible_agents, region_spec

DOMAIN = Domain(
    env_id="warehouse_v0",
    parallel_env=parallel_env,
    local_simulator=local_simulator,
    region_spec=region_spec,
    possible_agents=possible_agents,
    default_agents=("robot_20",),
    default_predictor="gru",
    episode_length=100,
    frame_stack=8,
    extra={"null_influence": 3, "uniform_influence": [[0.25, 0.25, 0.25, 0.25]] * 4},
)

__all__ = [
    "DOMAIN",
    "WarehouseEnv",
    "WarehouseLocalSimulator",
    "env",
    "parallel_env",
    "raw_env",
    "local_simulator",
    "region_spec",
    "possible_agents",
]
