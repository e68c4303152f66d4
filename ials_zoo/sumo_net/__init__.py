"""Traffic-signal control on any SUMO network (``sumo_net_v0``): RESCO's eight maps by name.

Modules: :mod:`~ials_zoo.sumo_net.scenario` (which files and hour), :mod:`~ials_zoo.sumo_net.network`
(the lights, read from the net file), :mod:`~ials_zoo.sumo_net.core` (RESCO's signal loop, where
libsumo lives), :mod:`~ials_zoo.sumo_net.mdp` (observations and rewards),
:mod:`~ials_zoo.sumo_net.metrics` (RESCO's delay from tripinfo), :mod:`~ials_zoo.sumo_net.env`
(the PettingZoo env), :mod:`~ials_zoo.sumo_net.controllers` (fixed time, max pressure, greedy).
"""
