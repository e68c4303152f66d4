"""Compatibility module: the SUMO cores (:mod:`ials_zoo.traffic.cores`) and the process lease
that runs them (:mod:`ials_zoo.traffic.lease`) under their former common name."""

from ials_zoo.traffic.cores import (  # noqa: F401
    PHASE_NAMES,
    YELLOW_STEPS,
    GridCore,
    LocalCore,
    observation,
)
from ials_zoo.traffic.lease import (  # noqa: F401
    BACKENDS,
    SimHandle,
    SimulationBusyError,
    SimulationError,
    WorkerDiedError,
    WorkerUnresponsiveError,
    inprocess_available,
)
