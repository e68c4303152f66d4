"""Traffic signal control on a SUMO grid (``traffic_grid_v0``, SPEC §2).

Modules: :mod:`~ials_zoo.traffic.network` (builds and caches the SUMO files),
:mod:`~ials_zoo.traffic.sim` (libsumo-safe simulation cores), :mod:`~ials_zoo.traffic.env`
(the global simulator), :mod:`~ials_zoo.traffic.local` (the local simulator),
:mod:`~ials_zoo.traffic.calibrate` (the demand calibration report).
"""

from ials_zoo.core.domains import Domain
from ials_zoo.traffic.env import parallel_env, possible_agents, region_spec
from ials_zoo.traffic.local import local_simulator

DOMAIN = Domain(
    env_id="traffic_grid_v0",
    parallel_env=parallel_env,
    local_simulator=local_simulator,
    region_spec=region_spec,
    possible_agents=possible_agents,
    default_agents=("tls_12", "tls_18"),
    default_predictor="mlp",
    episode_length=300,
    frame_stack=1,
    # untrained AIP: each lane gets a car w.p. 0.1 per step, the GS inflow rate (SPEC §3)
    extra={"null_influence": 0, "uniform_influence": [[0.9, 0.1]] * 4},
)

__all__ = ["DOMAIN"]
