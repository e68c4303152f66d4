"""The traffic global simulator: a SUMO grid of signalised intersections (PettingZoo)."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec, parallel_to_aec_wrapper

from ials_zoo.core.region import INFLUENCE_KEY, RegionSpec
from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.sumo.lease import SimHandle
from ials_zoo.traffic import network
from ials_zoo.traffic.cores import PHASE_NAMES, observation
from ials_zoo.traffic.network import APPROACHES, N_CELLS
from ials_zoo.traffic.render import render_grid
from ials_zoo.utils import check_reset_options, check_seed

SUMO_SEED_MAX = 2**31 - 2
"""The largest seed SUMO takes as it is (it reduces seeds modulo 2**31 - 1)."""

ENV_ID = "traffic_grid_v0"
OBS_SIZE = 4 * N_CELLS + 4
_OPTIONS = (
    "learners", "grid", "max_cycles", "inflow_probability", "warmup_steps", "backend",
    "render_mode", "scripted_learners", "internal_links",
)  # fmt: skip


def agent_name(index: int) -> str:
    return network.tls_id(index)


def possible_agents(grid=(5, 5), **_options) -> list[str]:
    """All intersections of a grid, ``tls_0`` .. ``tls_<rows*cols-1>``, row-major."""
    rows, cols = network.check_grid(grid)
    return [agent_name(i) for i in range(rows * cols)]


def agent_index(agent, grid=(5, 5)) -> int:
    """The row-major index of an agent name ``"tls_<i>"`` (an int index is accepted too)."""
    rows, cols = network.check_grid(grid)
    if isinstance(agent, (int, np.integer)) and not isinstance(agent, bool):
        idx = int(agent)
    elif isinstance(agent, str) and agent.startswith("tls_") and agent[4:].isdigit():
        idx = int(agent[4:])
    else:
        raise BadInput(
            f"unknown agent {agent!r}; agents are 'tls_0'..'tls_{rows * cols - 1}'"
        )
    if not 0 <= idx < rows * cols:
        raise BadInput(
            f"unknown agent {agent!r}: a {rows}x{cols} grid has 'tls_0'..'tls_{rows * cols - 1}'"
        )
    return idx


def dset_names() -> dict[str, tuple[str, ...]]:
    cells = tuple(f"occ_{a}_{k}" for a in APPROACHES for k in range(N_CELLS))
    return {"dset": cells, "full": cells + tuple(f"light_{p}" for p in PHASE_NAMES)}


def region_spec(
    agent, grid=(5, 5), inflow_probability=0.1, internal_links=True, **_options
) -> RegionSpec:
    """The region layout of one intersection, without building a simulator."""
    rows, cols = network.check_grid(grid)
    idx = agent_index(agent, (rows, cols))
    return RegionSpec(
        domain=ENV_ID,
        agent=agent_name(idx),
        influence_names=tuple(f"enter_{a}" for a in APPROACHES),
        influence_classes=(2, 2, 2, 2),
        dset_names=dset_names(),
        params={
            "grid": [rows, cols],
            "inflow_probability": network.check_probability(inflow_probability),
            "internal_links": network.check_bool("internal_links", internal_links),
        },
    )


def _check_int(name, value, low):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise BadInputType(f"{name} must be an int, got {value!r}")
    if value < low:
        raise BadInput(f"{name} must be >= {low}, got {value}")
    return int(value)


def check_action(agent, action) -> int:
    """A keep (0) / switch (1) action as an int; a clear error for anything else."""
    if action.__class__ is int and (action == 0 or action == 1):  # the common case, fast
        return action
    if isinstance(action, np.ndarray) and action.shape == ():
        action = action[()]
    if isinstance(action, (bool, np.bool_)) or not isinstance(action, (int, np.integer)):
        raise BadInputType(
            f"action of {agent!r} must be an int 0 (keep) or 1 (switch), got {action!r}"
        )
    if action not in (0, 1):
        raise BadInput(f"action of {agent!r} must be 0 (keep) or 1 (switch), got {action!r}")
    return int(action)


class TrafficGridEnv(ParallelEnv):
    """Traffic signal control on a SUMO grid (``traffic_grid_v0``, SPEC §2).

    A ``rows x cols`` grid (default 5 x 5) of signalised intersections, one lane per
    direction, every edge 100 m, speed limit 10 m/s, 1 s steps; each fringe entry inserts a
    car w.p. ``inflow_probability`` per step on a random route to a random exit (see
    :mod:`ials_zoo.traffic.network` for the demand, the vehicle model and the naming).
    Intersection ``i`` (row-major, row 0 north) is agent ``"tls_<i>"``; in the 5 x 5 grid
    ``tls_12`` is the centre. Non-learning intersections run SUMO's actuated program.

    **Agents**: the ``learners`` (default: every intersection). **Action**: ``Discrete(2)``,
    0 = keep the current green, 1 = switch; a switch shows yellow for 3 simulated seconds and
    then the other green; actions during the yellow are ignored. Learner lights are driven
    with ``trafficlight.setRedYellowGreenState`` (SUMO's "online" program) using the same 4
    states as the actuated program; they start in the north-south green (or, after a
    warm-up, in the actuated program's current/next green).

    **Observation**: ``Box(0, 1, (40,), float32)`` with 0/1 entries: for each incoming lane in
    the order N, E, S, W (the lane arriving from the northern neighbour first), 9 occupancy
    bits for the 10 m cells nearest the stop line (cell 0 = [0, 10) m before the stop line;
    a cell is 1 when a vehicle's front is in it), then a one-hot light state (NS green, NS
    yellow, EW green, EW yellow).

    **Reward**: the mean speed of the cars on the intersection's 4 incoming edges divided by
    10 (0 when they are empty), measured after the step.

    **Episode end**: truncation after ``max_cycles`` steps (default 300); no termination.
    Episodes start from an empty network, or after ``warmup_steps`` all-actuated steps.

    **Region data** (``ials_zoo.core.region``), per learner, the same keys, shapes and dtypes
    at reset and after every step: ``infos[a]["influence"]`` = 4 bits (N, E, S, W): a car
    entered that incoming lane from outside the region during the step (measured exactly: a
    vehicle id on the lane that was not on it at the previous step; fringe lanes include
    departures; all 0 at reset); ``infos[a]["dset"]`` = the 36 occupancy bits,
    ``infos[a]["dset_full"]`` = the 40-bit observation.

    **State** (``state()``, ``state_space``, for centralised critics): ``Box(0, 1, float32)``
    of ``40 * rows * cols`` entries: the 40-bit observation of every intersection, learners
    or not, in index order.

    **Options**: ``learners`` (agent names or indices), ``grid`` (2..10 per side),
    ``max_cycles``, ``inflow_probability``, ``warmup_steps``, ``backend``,
    ``render_mode`` (``"rgb_array"`` or ``"ansi"``), ``scripted_learners`` (learners are
    observed and rewarded but their lights keep the actuated program and actions are
    ignored: the actuated reference score), ``internal_links`` (default True: junctions have
    SUMO's internal lanes, so crossing takes time and space; False is about 1.6x faster in
    SUMO but changes the junction dynamics -- the calibration below is for True). Any other
    keyword (``**unknown`` in the signature) is refused, naming the valid options.

    **Rendering**: ``"rgb_array"`` draws a top view with numpy (grey roads, per intersection
    a north-south and an east-west mark coloured by its light, a magenta frame around each
    learner, blue dots for cars); ``"ansi"`` prints one line per grid row with, per learner,
    its light (``|`` NS green, ``-`` EW green, ``y`` yellow) and its number of occupied cells
    (``.``: not a learner); ``"human"`` prints the ``"ansi"`` view at every ``render()`` and
    returns None.

    **Seeding**: ``reset(seed=s)`` starts SUMO with ``--seed s``, for ``s`` in
    ``[0, 2**31 - 2]`` (SUMO's own range: it would reduce larger seeds modulo ``2**31 - 1``,
    so two seeds would give one episode; they are refused instead). The same seed and actions
    give the same trajectory. ``reset()`` without a seed draws one from the generator of the
    last explicit seed.

    **SUMO and libsumo**: all SUMO work runs in a simulation core with one call per step, via
    :class:`ials_zoo.sumo.lease.SimHandle`. ``backend="auto"`` (default) runs it in this
    process when no other libsumo simulation is live here, else in a worker process;
    ``"inprocess"`` raises ``SimulationBusyError`` when another simulation is live;
    ``"worker"`` always uses a process. A killed worker raises ``WorkerDiedError`` and the
    next ``reset()`` starts a new one; SUMO errors raise ``SimulationError``. ``close()``
    frees the simulation.

    **Calibration** (``ials-zoo calibrate --episodes 10 --steps 600``:
    5 x 5, every light actuated, from an empty network): about 100 / 176 / 254 / 288 cars
    at 50 / 100 / 200 / 300 s, an insertion backlog of about 1 car on average (at most 5)
    up to 300 s that grows after about 350 s (10 on average, up to 34, at 600 s), no
    teleports in 600 s; the actuated controller's mean episodic reward (300 steps) is about
    143 at ``tls_12`` and 149 at ``tls_18`` (the authors' Flow setup: about 162 and 167).

    Version history: v0 -- first version.
    """

    metadata = {
        "name": ENV_ID,
        "render_modes": ["rgb_array", "ansi", "human"],
        "is_parallelizable": True,
        "render_fps": 10,
    }

    def __init__(
        self,
        learners=None,
        grid=(5, 5),
        max_cycles: int = 300,
        inflow_probability: float = 0.1,
        warmup_steps: int = 0,
        backend: str = "auto",
        render_mode: str | None = None,
        scripted_learners: bool = False,
        internal_links: bool = True,
        **unknown,
    ):
        if unknown:
            raise BadInputType(
                f"unknown option(s) {sorted(unknown)} for {ENV_ID}; valid options: "
                f"{', '.join(_OPTIONS)}"
            )
        self.grid = network.check_grid(grid)
        self.max_cycles = _check_int("max_cycles", max_cycles, 1)
        self.warmup_steps = _check_int("warmup_steps", warmup_steps, 0)
        self.inflow_probability = network.check_probability(inflow_probability)
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise BadInput(
                f"unknown render_mode {render_mode!r}; expected None or one of "
                f"{self.metadata['render_modes']}"
            )
        self.render_mode = render_mode
        if not isinstance(scripted_learners, (bool, np.bool_)):
            raise BadInputType(f"scripted_learners must be a bool, got {scripted_learners!r}")
        self.scripted_learners = bool(scripted_learners)
        all_agents = possible_agents(self.grid)
        if learners is None:
            idx = list(range(len(all_agents)))
        else:
            if isinstance(learners, (str, int, np.integer)):
                learners = [learners]
            idx = [agent_index(a, self.grid) for a in learners]
            if not idx:
                raise BadInput("learners must name at least one intersection")
            if len(set(idx)) != len(idx):
                raise BadInput(f"duplicate learners in {learners!r}")
        self.learner_index = idx
        self.possible_agents = [all_agents[i] for i in idx]
        self.agents = []
        self._obs_space = spaces.Box(0.0, 1.0, (OBS_SIZE,), np.float32)
        self._act_space = spaces.Discrete(2)
        self.observation_spaces = {a: self._obs_space for a in self.possible_agents}
        self.action_spaces = {a: self._act_space for a in self.possible_agents}
        self.state_space = spaces.Box(0.0, 1.0, (OBS_SIZE * len(all_agents),), np.float32)
        self.internal_links = network.check_bool("internal_links", internal_links)
        self.files = network.build_grid(self.grid, self.inflow_probability, self.internal_links)
        config = {
            "net": self.files.net,
            "routes": self.files.routes,
            "tls_add": self.files.tls_additional,
            "observed": self.possible_agents,
            "lanes": [[e + "_0" for e in network.incoming_edges(self.grid, i)] for i in idx],
            "controlled": not self.scripted_learners,
            "states": self.files.meta["states"],
            "all_tls": all_agents,
            "all_lanes": [[e + "_0" for e in network.incoming_edges(self.grid, i)]
                          for i in range(len(all_agents))],
        }
        self._sim = SimHandle("ials_zoo.traffic.cores:GridCore", config, backend)
        self.backend = self._sim.mode
        self._seed_rng = np.random.default_rng()
        self._t = 0
        self._started = False
        self._phases = np.zeros(len(idx), np.int64)
        self._occ = np.zeros((len(idx), 4 * N_CELLS), np.uint8)

    # -- spaces
    def observation_space(self, agent):
        return self.observation_spaces[self._check_agent(agent)]

    def action_space(self, agent):
        return self.action_spaces[self._check_agent(agent)]

    def _check_agent(self, agent):
        if agent not in self.observation_spaces:
            raise BadInput(f"unknown agent {agent!r}; agents: {self.possible_agents}")
        return agent

    def region_spec(self, agent) -> RegionSpec:
        """The region layout of a learner (see :func:`region_spec`)."""
        self._check_agent(agent)
        return region_spec(agent, self.grid, self.inflow_probability, self.internal_links)

    # -- episode
    def reset(self, seed=None, options=None):
        """Start an episode (``options``: none are known; PettingZoo's API)."""
        check_reset_options(options)
        seed = check_seed(seed, upper=SUMO_SEED_MAX)
        if seed is not None:
            self._seed_rng = np.random.default_rng(seed)
            sumo_seed = seed
        else:
            sumo_seed = int(self._seed_rng.integers(SUMO_SEED_MAX + 1))
        occ, phases = self._sim.call("reset", sumo_seed, self.warmup_steps)
        self._started = True
        self._t = 0
        self.agents = list(self.possible_agents)
        self._occ, self._phases = occ, phases
        obs = observation(occ, phases)
        observations, infos = {}, {}
        for k, a in enumerate(self.agents):
            observations[a] = obs[k]
            infos[a] = {INFLUENCE_KEY: np.zeros(4, np.int64), "dset": occ[k].copy(),
                        "dset_full": obs[k].astype(np.uint8)}
        return observations, infos

    def step(self, actions):
        if not self.agents:
            raise RuntimeError("step() called on a finished episode; call reset() first")
        if not isinstance(actions, dict):
            raise BadInputType(f"actions must be a dict agent -> action, got {type(actions)}")
        extra = [a for a in actions if a not in self.observation_spaces]
        if extra:
            raise BadInput(f"actions for unknown agent(s) {extra}; agents: {self.agents}")
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise BadInput(f"missing actions for agent(s) {missing}")
        acts = np.array([check_action(a, actions[a]) for a in self.agents], np.int8)
        occ, entries, reward, phases = self._sim.call("step", acts)
        self._t += 1
        self._occ, self._phases = occ, phases
        obs = observation(occ, phases)
        # converted once for all agents; each agent gets its own row
        influence = entries.astype(np.int64)
        full = obs.astype(np.uint8)
        trunc = self._t >= self.max_cycles
        observations, rewards, terms, truncs, infos = {}, {}, {}, {}, {}
        for k, a in enumerate(self.agents):
            observations[a] = obs[k]
            rewards[a] = float(reward[k])
            terms[a] = False
            truncs[a] = trunc
            infos[a] = {
                INFLUENCE_KEY: influence[k],
                "dset": occ[k],
                "dset_full": full[k],
            }
        if trunc:
            self.agents = []
        return observations, rewards, terms, truncs, infos

    # -- extras
    def state(self) -> np.ndarray:
        """The global state (see the class docstring), float32."""
        if not self._started:
            raise RuntimeError("state() before reset()")
        return self._sim.call("state")

    def simulation_stats(self) -> dict:
        """Vehicles in the network, pending insertions, loaded/departed, teleports, time."""
        return self._sim.call("stats")

    def enable_metrics(self) -> None:
        """Record the queues at every step from now on, for :meth:`episode_metrics`."""
        self._sim.call("enable_metrics")

    def episode_metrics(self) -> dict[str, float]:
        """The episode's physical figures (call at its end): ``delay`` (mean time lost per
        arrived vehicle, SUMO's tripinfo timeLoss, s), ``waiting_time`` (mean seconds an arrived
        vehicle stood, s), ``throughput`` (vehicles arrived) and ``queue`` (mean halting vehicles
        on the lanes entering the intersections; after :meth:`enable_metrics`)."""
        return self._sim.call("episode_metrics")

    def sumo_query(self, domain: str, method: str, *args):
        """Call a libsumo getter on this env's simulation, e.g. ``("lane", "getLength", id)``."""
        return self._sim.call("query", domain, method, *args)

    def render(self):
        if self.render_mode is None:
            return None
        if self.render_mode == "ansi":
            return self._render_ansi()
        if self.render_mode == "human":
            print(self._render_ansi(), flush=True)
            return None

        return render_grid(self.grid, self._sim.call("render_data"), learners=self.learner_index)

    def _render_ansi(self) -> str:
        rows, cols = self.grid
        sym = {0: "|", 1: "y", 2: "-", 3: "y"}
        lines = [f"t={self._t}"]
        by_index = {i: k for k, i in enumerate(self.learner_index)}
        for r in range(rows):
            cells = []
            for c in range(cols):
                k = by_index.get(r * cols + c)
                if k is None:
                    cells.append("  .  ")
                else:
                    cells.append(f"{sym[int(self._phases[k])]}{int(self._occ[k].sum()):>3d} ")
            lines.append("".join(cells))
        return "\n".join(lines)

    def close(self):
        sim = getattr(self, "_sim", None)
        if sim is not None:
            sim.close()
        self.agents = []

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def raw_env(**options):
    """The AEC version of the GS without wrappers (PettingZoo's ``raw_env`` convention)."""
    return parallel_to_aec_wrapper(TrafficGridEnv(**options))


def parallel_env(**options) -> TrafficGridEnv:
    """``traffic_grid_v0`` as a PettingZoo ``ParallelEnv``."""
    return TrafficGridEnv(**options)


def env(**options):
    """``traffic_grid_v0`` as a PettingZoo AEC env (via ``parallel_to_aec``)."""
    return parallel_to_aec(parallel_env(**options))
