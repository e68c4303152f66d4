"""Traffic-signal control on any SUMO network, RESCO's maps by name, version 0 (see ``ials_zoo.sumo_net.env``)."""

from ials_zoo.sumo_net.env import env, parallel_env, raw_env

__all__ = ["env", "parallel_env", "raw_env"]
