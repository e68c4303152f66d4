"""Traffic signal control on a SUMO grid (``traffic_grid_v0``, SPEC §2).

Modules: :mod:`~ials_zoo.traffic.network` (builds and caches the SUMO files),
:mod:`~ials_zoo.traffic.cores` (the simulation cores), :mod:`~ials_zoo.sumo.lease` (where a
simulation runs: this process or a worker), :mod:`~ials_zoo.traffic.env` (the global
simulator), :mod:`~ials_zoo.traffic.local` (the local simulator),
:mod:`~ials_zoo.traffic.calibrate` (the demand calibration report),
:mod:`~ials_zoo.traffic.benchmark` (raw SUMO vs GS vs LS speed), :mod:`~ials_zoo.traffic.domain`
(the :class:`~ials_zoo.core.Domain` of the zoo).
"""

from ials_zoo.traffic.domain import DOMAIN

__all__ = ["DOMAIN"]
