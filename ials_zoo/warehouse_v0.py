"""Warehouse commissioning, version 0: 36 robots collecting items (see ``ials_zoo.warehouse.env``)."""

from ials_zoo.warehouse.env import env, parallel_env, raw_env

__all__ = ["env", "parallel_env", "raw_env"]
