"""Warehouse commissioning (``warehouse_v0``, SPEC §1): 36 robots fetch items from shelves.

* :mod:`ials_zoo.warehouse.regions` -- floor/region layout, item-bit order, influence sources,
  movement and shortest-path tables, the item process shared by the GS and the LS.
* :mod:`ials_zoo.warehouse.env` -- the global simulator, :class:`WarehouseEnv` (PettingZoo).
* :mod:`ials_zoo.warehouse.local` -- the local simulator, :class:`WarehouseLocalSimulator`.
* :mod:`ials_zoo.warehouse.render` -- images and the text view.
* :mod:`ials_zoo.warehouse.domain` -- the :class:`~ials_zoo.core.Domain` of the zoo.
"""

from ials_zoo.warehouse.domain import DOMAIN
from ials_zoo.warehouse.env import WarehouseEnv, env, parallel_env, raw_env
from ials_zoo.warehouse.local import WarehouseLocalSimulator, local_simulator
from ials_zoo.warehouse.regions import possible_agents, region_spec

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
