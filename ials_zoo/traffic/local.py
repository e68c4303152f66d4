"""The traffic local simulator: one intersection alone, in SUMO (SPEC §2, §5)."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from ials_zoo.core.local import LocalSimulator, agent_list, check_n_envs
from ials_zoo.core.streams import CopyStreams
from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.sumo.lease import SimHandle
from ials_zoo.traffic import network
from ials_zoo.traffic.cores import observation
from ials_zoo.traffic.env import OBS_SIZE, agent_index, region_spec
from ials_zoo.utils import check_seed


class TrafficLocalSimulator(LocalSimulator):
    """``n_envs`` copies of each of ``agents``' intersections, with their 4 incoming and 4
    outgoing 100 m edges, in ONE SUMO network: one ``simulationStep()`` advances them all.

    Same geometry, vehicle model, light control (keep/switch with 3 s yellow), observation,
    reward and d-sets as :class:`~ials_zoo.traffic.env.TrafficGridEnv` -- the observation code
    is shared (:class:`ials_zoo.traffic.cores._LaneReader`). The copies are disjoint
    intersections; they differ by the turning flows of their intersection.

    Each step, for every copy and incoming lane (N, E, S, W) whose influence bit is 1, a car
    is inserted at the start of that lane (``departSpeed=10``; dropped if it cannot be
    inserted at once, as the GS car would not have entered then). Its turn (right, straight,
    left) is drawn from the GS's expected turning statistics at the copy's intersection
    (:func:`ials_zoo.traffic.network.turn_probabilities`: exact under the grid's route
    distributions, ignoring congestion), or from ``turn_probabilities`` (a ``[4, 3]`` array
    for every agent, or ``[len(agents), 4, 3]``) if given. Cars leave at the end of the
    outgoing edges, so spill-back from downstream intersections is not modelled (it is not an
    influence source in SPEC §2).

    Args:
        agents: the GS agent(s) whose regions these are, e.g. ``"tls_12"`` or a list.
        n_envs: copies per agent.
        grid, inflow_probability, internal_links: the GS setting (for the turning
            statistics, the junction model and the region's parameters).
        max_cycles: episode length (the caller truncates).
        backend: ``"auto"`` / ``"inprocess"`` / ``"worker"`` (see
            :mod:`ials_zoo.sumo.lease`).
        turn_probabilities: optional override of the turning probabilities.

    Attributes:
        last_entries: ``[n_copies, 4]`` uint8, the cars that actually entered each incoming
            lane during the last step (measured like the GS's influence bits).
    """

    def __init__(
        self,
        agents="tls_12",
        n_envs: int = 1,
        grid=(5, 5),
        inflow_probability: float = 0.1,
        max_cycles: int = 300,
        backend: str = "auto",
        turn_probabilities=None,
        internal_links: bool = True,
        **unknown,
    ):
        if unknown:
            raise BadInputType(
                f"unknown option(s) {sorted(unknown)} for the traffic local simulator; valid: "
                "agents, n_envs, grid, inflow_probability, max_cycles, backend, "
                "turn_probabilities, internal_links"
            )
        self.grid = network.check_grid(grid)
        self.n_envs = check_n_envs(n_envs)
        agents = agent_list([agents] if isinstance(agents, (int, np.integer)) else agents)
        self.indices = [agent_index(a, self.grid) for a in agents]
        self.regions = tuple(region_spec(i, self.grid, inflow_probability, internal_links)
                             for i in self.indices)
        self.agents = tuple(r.agent for r in self.regions)
        if len(set(self.agents)) != len(self.agents):
            raise BadInput(f"agents repeat: {list(agents)}")
        if isinstance(max_cycles, bool) or not isinstance(max_cycles, (int, np.integer)):
            raise BadInputType(f"max_cycles must be an int, got {max_cycles!r}")
        if max_cycles < 1:
            raise BadInput(f"max_cycles must be >= 1, got {max_cycles}")
        self.max_cycles = int(max_cycles)
        n = self.n_copies
        self.files = network.build_local(n, internal_links)
        self.observation_space = spaces.Box(0.0, 1.0, (OBS_SIZE,), np.float32)
        self.action_space = spaces.Discrete(2)
        if turn_probabilities is None:
            probs = np.stack([network.turn_probabilities(self.grid, i, inflow_probability)
                              for i in self.indices])
        else:
            probs = np.asarray(turn_probabilities, dtype=np.float64)
            if probs.shape == (4, 3):
                probs = np.broadcast_to(probs, (len(self.agents), 4, 3))
            if (probs.shape != (len(self.agents), 4, 3) or (probs < 0).any()
                    or not np.allclose(probs.sum(-1), 1)):
                raise BadInput(
                    "turn_probabilities must be a [4, 3] (or [agents, 4, 3]) array of rows "
                    f"(right, straight, left) summing to 1, got {turn_probabilities!r}"
                )
        self.turn_probabilities = probs
        # per copy (agent-major), the cumulative probabilities of 'right' and 'straight'
        self._cum = np.repeat(np.cumsum(probs, axis=-1)[:, :, :2], self.n_envs, axis=0)
        config = {
            "net": self.files.net,
            "routes": self.files.routes,
            "n": n,
            "states": self.files.meta["states"],
            "route_ids": self.files.meta["routes"],
        }
        self._sim = SimHandle("ials_zoo.traffic.cores:LocalCore", config, backend)
        self.backend = self._sim.mode
        # turn draws: one uniform per (agent, copy) and lane each step (ials_zoo.core.streams)
        self._streams = CopyStreams(self.agents, self.n_envs, 4)
        self._sumo_seeds = np.random.default_rng()
        self._started = False
        self.last_entries = np.zeros((n, 4), np.uint8)

    @property
    def agent(self) -> str:
        """The agent of a single-agent local simulator."""
        return self.region.agent

    @property
    def index(self) -> int:
        """The intersection index of a single-agent local simulator."""
        return agent_index(self.agent, self.grid)

    def reset(self, seed: int | None = None):
        seed = check_seed(seed)
        if seed is not None:
            self._streams.seed(seed)
            self._sumo_seeds = np.random.default_rng(seed)
        # nothing in the LS draws from SUMO's random numbers (see LocalCore.reset); seeded anyway
        sumo_seed = int(self._sumo_seeds.integers(2**31 - 1))
        occ, phases = self._sim.call("reset", sumo_seed)
        self._started = True
        obs = observation(occ, phases)
        self.last_entries = np.zeros((self.n_copies, 4), np.uint8)
        return obs, {"dset": occ, "full": obs.astype(np.uint8)}

    def step(self, actions, influences):
        if not self._started:
            raise RuntimeError("step() before reset()")
        n = self.n_copies
        actions = np.asarray(actions)
        if actions.shape != (n,) or actions.dtype.kind not in "iu":
            raise BadInput(
                f"actions must be an int array of shape ({n},), got {actions!r} "
                f"(dtype {actions.dtype})"
            )
        if n == 1:  # scalar compares beat any numpy call here
            if actions[0] != 0 and actions[0] != 1:
                raise BadInput(f"actions must be 0 (keep) or 1 (switch), got {actions!r}")
        elif (actions >> 1).any():
            # one shift instead of np.isin (a tenth of the step's Python time): only 0 and 1
            # (and no negative number) shift to 0
            raise BadInput(f"actions must be 0 (keep) or 1 (switch), got {actions!r}")
        influences = np.asarray(influences)
        if influences.shape != (n, 4) or influences.dtype.kind not in "iub":
            raise BadInput(
                f"influences must be an int array of shape ({n}, 4), got shape "
                f"{influences.shape} dtype {influences.dtype}"
            )
        draws = self._streams.next()  # one per copy and lane, used or not: streams stay aligned
        ks, lanes = np.nonzero(influences)
        if len(ks):
            if len(ks) != influences.sum():
                raise BadInput(f"influence bits must be 0 or 1, got {influences!r}")
            u = draws[ks, lanes]
            turns = (u[:, None] >= self._cum[ks, lanes]).sum(axis=1)
            inserts = list(zip(ks.tolist(), lanes.tolist(), turns.tolist()))
        else:
            inserts = []
        occ, entries, reward, phases = self._sim.call("step", actions, inserts)
        self.last_entries = entries
        obs = observation(occ, phases)
        return obs, reward, {"dset": occ, "full": obs.astype(np.uint8)}

    def sumo_query(self, domain: str, method: str, *args):
        """Call a libsumo getter on this simulator's SUMO (tests, diagnostics)."""
        return self._sim.call("query", domain, method, *args)

    def close(self) -> None:
        sim = getattr(self, "_sim", None)
        if sim is not None:
            sim.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def local_simulator(agents, n_envs: int = 1, **options) -> TrafficLocalSimulator:
    """The domain registry's LS factory. Accepts the GS options ``grid``,
    ``inflow_probability``, ``internal_links``, ``max_cycles`` and ``backend`` (other GS-only
    options like ``learners`` are ignored)."""
    for gs_only in ("learners", "warmup_steps", "render_mode", "scripted_learners"):
        options.pop(gs_only, None)
    return TrafficLocalSimulator(agents, n_envs=n_envs, **options)
