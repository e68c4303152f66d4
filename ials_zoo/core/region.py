"""The region interface: what every domain exposes about one agent's neighbourhood.

The influence-based abstraction (paper §3) splits the global state, from one agent's point of
view, into

* the **local state** ``x_t`` -- the variables of the agent's region (its observation is a
  function of it);
* the **influence sources** ``u_t`` -- the few external variables that directly change the
  region (one categorical variable per source, e.g. "which shared shelf cell the right-hand
  neighbour stands on");
* the **d-set** ``d_t`` -- the part of the local history the influence predictor may condition
  on (paper §4.2). Every domain offers two kinds: ``"dset"``, the paper's minimal d-set, and
  ``"full"``, the whole observation (for the d-set ablation).

Every global simulator (GS) of the zoo reports, for each *learning* agent, in its ``infos``:

* after ``reset``: ``infos[agent]["dset"]`` and ``infos[agent]["dset_full"]`` -- ``d_0``;
* after each ``step``: ``infos[agent]["influence"]`` -- ``u_t``, the influence sources that
  acted during the step just taken (int64, shape ``(M,)``), and the two d-sets of the new
  state, ``d_{t+1}``.

So a collector pairs ``d_t`` (from the previous call) with ``u_t`` (from this step), which is
exactly the ``(l_t, u_t)`` pair of Algorithm 1, and a local simulator consumes ``u_t``
sampled from ``P(u_t | d_0..d_t)`` to produce ``x_{t+1}`` (Algorithm 2).

Every domain also offers ``env.region_spec(agent) -> RegionSpec`` describing the fixed
layout of these arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from gymnasium import spaces

from ials_zoo.errors import BadInput

DSET_KINDS = ("dset", "full")
"""The d-set kinds: the paper's minimal d-set, or the agent's whole observation."""

INFLUENCE_KEY = "influence"


def dset_key(kind: str) -> str:
    """The ``infos`` key under which a GS reports the d-set of ``kind``."""
    check_dset_kind(kind)
    return "dset" if kind == "dset" else "dset_full"


def check_dset_kind(kind: str) -> str:
    if kind not in DSET_KINDS:
        raise BadInput(f"unknown d-set kind {kind!r}; expected one of {DSET_KINDS}")
    return kind


@dataclass(frozen=True)
class RegionSpec:
    """The fixed layout of one agent's region data.

    Attributes:
        domain: versioned domain id, e.g. ``"warehouse_v0"``.
        agent: the agent id in the GS, e.g. ``"robot_20"``.
        influence_names: one name per influence source, in array order.
        influence_classes: number of classes of each source (2 for a bit).
        dset_names: for each d-set kind, one name per bit, in array order.
        params: the GS parameters that change the region's statistics (grid size, item
            probability, ...), so that an influence predictor trained for one setting is not
            silently used for another.
    """

    domain: str
    agent: str
    influence_names: tuple[str, ...]
    influence_classes: tuple[int, ...]
    dset_names: dict[str, tuple[str, ...]]
    params: dict = field(default_factory=dict)

    def __post_init__(self):
        if len(self.influence_names) != len(self.influence_classes):
            raise BadInput("influence_names and influence_classes differ in length")
        if set(self.dset_names) != set(DSET_KINDS):
            raise BadInput(f"dset_names must define exactly the kinds {DSET_KINDS}")

    @property
    def n_sources(self) -> int:
        return len(self.influence_names)

    @property
    def influence_space(self) -> spaces.MultiDiscrete:
        return spaces.MultiDiscrete(np.array(self.influence_classes, dtype=np.int64))

    def dset_size(self, kind: str = "dset") -> int:
        return len(self.dset_names[check_dset_kind(kind)])

    def dset_space(self, kind: str = "dset") -> spaces.MultiBinary:
        return spaces.MultiBinary(self.dset_size(kind))

    def to_dict(self) -> dict:
        return {
            "domain": self.domain,
            "agent": self.agent,
            "influence_names": list(self.influence_names),
            "influence_classes": list(self.influence_classes),
            "dset_names": {k: list(v) for k, v in self.dset_names.items()},
            "params": dict(self.params),
        }

    @classmethod
    def from_dict(cls, data: dict) -> RegionSpec:
        return cls(
            domain=data["domain"],
            agent=data["agent"],
            influence_names=tuple(data["influence_names"]),
            influence_classes=tuple(int(c) for c in data["influence_classes"]),
            dset_names={k: tuple(v) for k, v in data["dset_names"].items()},
            params=dict(data.get("params", {})),
        )
