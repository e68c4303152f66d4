"""The registry of domains: how generic code (data collection, the IALS factory, baselines,
the evaluator) finds a domain's global simulator, local simulator and regions.

Adding a domain means adding one folder ``ials_zoo/<domain>/`` whose ``__init__`` defines a
module-level ``DOMAIN = Domain(...)``, and one line in ``_DOMAIN_MODULES``.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Callable

from ials_zoo.core.local import LocalSimulator
from ials_zoo.core.region import RegionSpec


@dataclass(frozen=True)
class Domain:
    """What a domain provides to the rest of the zoo.

    Attributes:
        env_id: versioned id, e.g. ``"warehouse_v0"``.
        parallel_env: ``parallel_env(**options) -> pettingzoo.ParallelEnv`` (the GS).
        local_simulator: ``local_simulator(agent, n_envs=1, **options) -> LocalSimulator``.
        region_spec: ``region_spec(agent, **options) -> RegionSpec`` without building a GS.
        possible_agents: ``possible_agents(**options) -> list[str]``.
        default_agents: the agents the paper trained (whose AIPs ship with the package).
        default_predictor: ``"gru"`` or ``"mlp"``, the AIP architecture the paper used.
        episode_length: default episode length (steps).
        frame_stack: how many observations the paper's policy reads (1 = current only).
        uniform_influence: class probabilities of the *untrained* AIP (one list per source
            kind; SPEC §3: 0.25 per class in the warehouse, 0.1 per lane in traffic).
    """

    env_id: str
    parallel_env: Callable
    local_simulator: Callable[..., LocalSimulator]
    region_spec: Callable[..., RegionSpec]
    possible_agents: Callable[..., list]
    default_agents: tuple[str, ...]
    default_predictor: str
    episode_length: int
    frame_stack: int = 1
    extra: dict = field(default_factory=dict)


_DOMAIN_MODULES = {
    "warehouse_v0": "ials_zoo.warehouse",
    "traffic_grid_v0": "ials_zoo.traffic",
}


def domain_ids() -> list[str]:
    return list(_DOMAIN_MODULES)


def get_domain(env_id: str) -> Domain:
    """Look up a domain by its versioned id; a clear error for an unknown one."""
    try:
        module_name = _DOMAIN_MODULES[env_id]
    except KeyError:
        raise ValueError(
            f"unknown domain {env_id!r}; available: {', '.join(_DOMAIN_MODULES)}"
        ) from None
    return importlib.import_module(module_name).DOMAIN
