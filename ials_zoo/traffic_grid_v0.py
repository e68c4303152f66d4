"""Traffic signal control on a 5x5 SUMO grid, version 0 (see ``ials_zoo.traffic.env``)."""

from ials_zoo.traffic.env import env, parallel_env, raw_env

__all__ = ["env", "parallel_env", "raw_env"]
