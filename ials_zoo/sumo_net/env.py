"""``sumo_net_v0``: traffic-signal control on any SUMO network, RESCO's MDP by default (PettingZoo)."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from dataclasses import asdict

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec, parallel_to_aec_wrapper

from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.sumo.command import load_budget
from ials_zoo.sumo.lease import SimHandle
from ials_zoo.sumo_net.core import MEASURES
from ials_zoo.sumo_net.influence import full_dset, region_layout, region_spec
from ials_zoo.sumo_net.mdp import (
    BATCHED_OBSERVATIONS,
    GREEN_OBSERVATIONS,
    N_FEATURES,
    WAVE_OBSERVATIONS,
    drq_wave,
    lanes_tables,
    mplight,
    observation_fn,
    reward_fn,
)
from ials_zoo.sumo_net.metrics import episode_metrics, scheduled_departures
from ials_zoo.sumo_net.names import ENV_ID, OPTIONS, SCENARIO_OPTIONS
from ials_zoo.sumo_net.network import read_network
from ials_zoo.sumo_net.pressure import Pressures
from ials_zoo.sumo_net.render import NetworkView
from ials_zoo.sumo_net.scenario import scenario_of
from ials_zoo.sumo_net.waves import DISTANCE as WAVE_DISTANCE
from ials_zoo.sumo_net.waves import Waves
from ials_zoo.utils import check_reset_options, check_seed

SUMO_SEED_MAX = 2**31 - 2


def possible_agents(**options) -> list[str]:
    """Every signalised junction of the network the options name (traffic-light ids, file order)."""
    scenario = scenario_of(**{k: options[k] for k in SCENARIO_OPTIONS if k in options})
    return read_network(scenario.net_file).ids


def _check_distance(value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or not value > 0:
        raise BadInput(f"max_distance must be a positive number of metres, got {value!r}")
    return float(value)


QUEUE = MEASURES.index("queue")


def _observation_spaces(lights, observe) -> dict:
    """RESCO's lanes tables (5 entries per incoming lane), 2 entries per green (MPLight's, wave),
    or both (drq_wave)."""
    if observe in GREEN_OBSERVATIONS:
        return {x.id: spaces.Box(-np.inf, np.inf, (2 * x.n_actions,), np.float32) for x in lights}
    extra = 2 if observe is drq_wave else 0
    return {x.id: spaces.Box(0.0, np.inf, (N_FEATURES * len(x.lanes) + extra * x.n_actions,), np.float32)
            for x in lights}


PROGRAMS = {True: "fixed", "fixed": "fixed", "actuated": "actuated"}


def _program_of(scripted_learners) -> str | None:
    """``scripted_learners``: False (the learners act), True or ``"fixed"`` (they run the
    network's own program), ``"actuated"`` (SUMO's actuated control of it)."""
    if scripted_learners is False or scripted_learners is None:
        return None
    try:
        return PROGRAMS[scripted_learners]
    except (KeyError, TypeError):
        raise BadInput(f"scripted_learners must be False, True, 'fixed' or 'actuated', got {scripted_learners!r}") \
            from None


def _learner_ids(learners, all_ids: list[str]) -> list[str]:
    if learners is None:
        return list(all_ids)
    if isinstance(learners, str):
        learners = [x.strip() for x in learners.split(",") if x.strip()]
    learners = list(learners)
    unknown = [x for x in learners if x not in all_ids]
    if unknown:
        shown = ", ".join(all_ids[:8]) + (f", ... ({len(all_ids)} in all)" if len(all_ids) > 8 else "")
        raise BadInput(f"learners: unknown traffic light(s) {unknown}; this network has {shown}")
    if len(set(learners)) != len(learners):
        raise BadInput(f"learners: duplicates in {learners}")
    return [x for x in all_ids if x in learners]  # network order


class SumoNetEnv(ParallelEnv):
    """Traffic-signal control on any SUMO network (``sumo_net_v0``), RESCO's MDP by default.

    **Networks**: ``net=`` (default ``"cologne8"``) one of RESCO's maps (grid4x4, arterial4x4, cologne1, cologne3,
    cologne8, ingolstadt1, ingolstadt7, ingolstadt21; files from the ``sumo-rl`` wheel), a grid
    of any size ``"gridRxC"`` (2 to 20 rows and columns, built at first use and cached: DIALS's
    grid of single-lane 100 m roads, a vehicle entering each fringe road with probability 0.1 a
    second), ``sumocfg=PATH``, or ``net_file=PATH`` with ``route_files=``; ``begin``/``end`` (s) override
    the map's hour (Cologne 25,200-28,800, Ingolstadt 57,600-61,200, the grids 0-3,600). Known
    differences of the wheel's files from RESCO's (Ault & Sharon, NeurIPS 2021 Datasets and
    Benchmarks; github Pi-Star-Lab/RESCO): ingolstadt7 and ingolstadt21 lack one 25 s green of
    one junction (3 actions there, 4 in RESCO), and grid4x4/arterial4x4 have only their first
    per-episode route file (here every episode uses it, with its own SUMO seed).

    **Agents**: every signalised junction (a ``tlLogic`` that controls a lane) with at least two
    greens, named by its traffic-light id; a light of one green (the corners of a grid made by
    ``netgenerate``) has no choice to learn and runs its own program. ``learners`` (default: all)
    are driven by actions; the others run the network's own program.

    **Action** (RESCO's): ``Discrete(n)``, ``n`` = the light's green phases in program 0
    (phases with no ``y`` and some ``g``/``G``, file order; 2 to 8 on RESCO's maps). A change
    of green shows RESCO's yellow first (3 s; arterial4x4 2 s); there is no minimum green.

    **Step**: one decision every ``decision_seconds`` of simulated time (10; arterial4x4 5),
    1 s SUMO steps, ``--time-to-teleport -1`` (no teleports). See :mod:`ials_zoo.sumo_net.core`
    for RESCO's signal loop, which this reproduces (its yellows, ``setPhase`` on the net's phase
    durations, its detection within ``max_distance`` m and its wait bookkeeping).

    **Observation** (``observation="drq_norm"``, RESCO's for IDQN and IPPO):
    ``Box(0, inf, (5 * lanes,), float32)``, per incoming lane in controlled-link order
    ``[lane index == current phase index, approach / 28, total wait / 28, queue / 28, speed sum
    / 560]`` (row-major). ``"drq"``: the same without the scaling. ``"mplight"`` (MPLight's, on
    our greens): ``Box(-inf, inf, (2 * greens,))``, each green's pressure (the queue on the
    lanes it lets go minus the queue where their outgoing edges enter another light;
    :mod:`ials_zoo.sumo_net.pressure`), then a one-hot of the current green. ``"wave"``
    (greedy's input): ``Box(0, inf, (2 * greens,))``, each green's vehicles within 50 m on the
    lanes it lets go, over 28 (:mod:`ials_zoo.sumo_net.waves`), then the one-hot. ``"drq_wave"``:
    ``drq_norm``'s table, then ``wave``'s. What a light
    observes changes neither the episode nor its reward: a board entry may name it.

    **Reward** (``reward="wait_norm"``, RESCO's): ``clip(-total wait / 224, -4, 4)`` of the
    light's detected vehicles; ``"wait"``, ``"queue"`` and ``"pressure"`` (RESCO's for MPLight:
    minus the light's pressure) are offered too. ``mplight``, the waves and ``pressure`` read what
    a region does not count: the GS takes them, a light's IALS does not.

    **Episode end**: truncation when SUMO's clock reaches ``end`` (360 decisions on RESCO's maps;
    ``max_cycles=N``: after N decisions, for short tests).

    **Metrics** (``episode_metrics()`` after the last step; ``ials_zoo.sumo_net.metrics``):
    RESCO's average delay per vehicle (``delay``, from SUMO's tripinfo as RESCO reads it),
    ``delay_all``, ``trip_time``, ``waiting_time``, ``throughput``, ``vehicles`` and ``queue``
    (the mean over decisions of the mean over lights of their detected queue).

    **State** (``state()``): every light's observation, concatenated in network order.

    **Seeding**: ``reset(seed=s)`` runs SUMO with ``--seed s``; the same seed and actions give
    the same episode, the one a plain ``sumo`` process gives. **SUMO**: one core call per
    decision through :class:`ials_zoo.sumo.lease.SimHandle`. By default (``fresh_process=True``,
    ``backend="worker"``) every episode runs in a new worker process: with SUMO 1.28 a second
    libsumo simulation in one process can differ from the first on maps of ``<trip>`` routes
    (cologne1, seed 3: 43.30 or 44.31 s of delay, at random), so only a fresh process makes
    episodes reproducible. The process is forked from a zygote that imported libsumo but never
    ran a simulation, so it starts in milliseconds. ``fresh_process=False`` with
    ``backend="auto"``/``"inprocess"`` also saves the pipe round trip per decision, at that price.

    **Rendering**: ``"rgb_array"`` (a top view: roads, vehicles, each incoming lane's signal,
    learners ringed; :mod:`ials_zoo.sumo_net.render`), ``"ansi"`` (one line per light: its phase
    and queue), ``"human"`` prints the ``"ansi"`` view.

    **Other options**: ``region_data=True`` has the GS watch its learners' regions every second
    and report each one's influence sources and d-set in ``infos`` (what AIP data is collected
    from; a cost, so off by default). ``scripted_learners=True`` (or ``"fixed"``) has the learners
    run the network's own program, ``"actuated"`` SUMO's actuated control of it: they are still
    observed and rewarded, their actions ignored (the zoo's ``scripted`` reference and the rules
    ``fixed`` and ``actuated``; :mod:`ials_zoo.sumo_net.controllers`). Any other keyword (``**unknown`` in the signature) is
    refused, naming the valid options.

    **IALS**: every light's IALS is :class:`ials_zoo.sumo_net.ials_env.IALSNetEnv` (and
    ``make_ials_parallel_env``); its regions run in SUMO (``local="sumo"``) or as numpy arrays,
    every copy in one batch, without SUMO (``local="arrays"``: :mod:`ials_zoo.sumo_net.arrays`;
    ``ials-zoo train dials --local arrays``). Their fidelity and cost: ``docs/local_simulators.md``.

    Version history: v0 -- first version.
    """

    metadata = {"name": ENV_ID, "render_modes": ["rgb_array", "ansi", "human"], "is_parallelizable": True,
                "render_fps": 10}
    CORE = "ials_zoo.sumo_net.core:NetCore"  # the simulation core (``"package.module:Class"``)
    REGION_CORE = "ials_zoo.sumo_net.influence:RegionNetCore"  # the core that watches the learners' regions
    NETWORK_WIDE = True  # observations and rewards may read other lights (MPLight's): the whole network is here
    HANDLE = SimHandle  # where the core runs (a core without SUMO: :class:`ials_zoo.sumo.lease.PlainHandle`)

    def __init__(self, net=None, sumocfg=None, net_file=None, route_files=None, begin=None, end=None,
                 decision_seconds=None, yellow_seconds=None, max_cycles=None, learners=None, max_distance=200.0,
                 observation="drq_norm", reward="wait_norm", backend="worker", fresh_process=True, render_mode=None,
                 scripted_learners=False, region_data=False, **unknown):
        self.program = _program_of(scripted_learners)
        if unknown:
            raise BadInputType(f"unknown option(s) {sorted(unknown)} for {ENV_ID}; valid options: {', '.join(OPTIONS)}")
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise BadInput(f"unknown render_mode {render_mode!r}; expected None or one of {self.metadata['render_modes']}")
        self.render_mode = render_mode
        self._observe = observation_fn(observation, self.NETWORK_WIDE)
        self._reward = reward_fn(reward, self.NETWORK_WIDE)  # None: RESCO's pressure, every light at once
        self.scenario = scenario_of(net, sumocfg, net_file, route_files, begin, end, decision_seconds, yellow_seconds,
                                    max_cycles)
        given = dict(net=net, sumocfg=sumocfg, net_file=net_file, route_files=route_files, begin=begin, end=end,
                     decision_seconds=decision_seconds, yellow_seconds=yellow_seconds, max_cycles=max_cycles)
        self._scenario_options = {k: v for k, v in given.items() if v is not None}
        self.network = read_network(self.scenario.net_file)
        # the route files read whole before any step: a broken one is refused here, not after an
        # episode run on part of its demand (the metrics read the same schedule every episode)
        self._schedule = scheduled_departures(self.scenario.route_files)
        self.max_distance = _check_distance(max_distance)
        self.possible_agents = _learner_ids(learners, self.network.ids)
        self.agents = []
        lights = self.network.lights
        self._rows = np.cumsum([0] + [len(x.lanes) for x in lights]).tolist()
        self._starts = np.asarray(self._rows, np.int64)
        self._index = {x.id: k for k, x in enumerate(lights)}
        wide = self._observe is mplight or self._reward is None
        self._pressures = Pressures(self.network) if wide else None
        self._waves = Waves(self.network) if self._observe in WAVE_OBSERVATIONS else None
        self.observation_spaces = _observation_spaces(lights, self._observe)
        self.action_spaces = {x.id: spaces.Discrete(x.n_actions) for x in lights}
        width = sum(s.shape[0] for s in self.observation_spaces.values())
        low = -np.inf if self._observe is mplight else 0.0
        self.state_space = spaces.Box(low, np.inf, (width,), np.float32)
        if not isinstance(fresh_process, (bool, np.bool_)):
            raise BadInputType(f"fresh_process must be a bool, got {fresh_process!r}")
        if fresh_process and backend != "worker":
            raise BadInput(f"fresh_process=True runs every episode in a new worker: backend must be 'worker', "
                           f"not {backend!r} (or pass fresh_process=False)")
        self.fresh_process = bool(fresh_process)
        if not isinstance(region_data, (bool, np.bool_)):
            raise BadInputType(f"region_data must be a bool, got {region_data!r}")
        self.region_data = bool(region_data)
        if self.region_data:  # the learners' regions watched every second (a cost): for AIP data
            self.CORE = self.REGION_CORE
        self._region = None
        self._region_rows = {a: k for k, a in enumerate(self.possible_agents)}  # the core's region data rows
        self._tmp = tempfile.mkdtemp(prefix="ials_zoo_sumo_net_")  # the episodes' tripinfo, read and removed
        s = self.scenario  # a large network loads for a while: its load is budgeted by its size
        self._sim = self.HANDLE(self.CORE, self._core_config(), backend,
                                load_seconds=load_budget(s.net_file, *s.route_files))
        self.backend = self._sim.mode
        self._seed_rng = np.random.default_rng()
        self._measures, self._phases, self._time = None, None, 0.0
        self._metrics, self._episodes, self._tripinfo = None, 0, None
        self._unread_tripinfo = None  # the ended episode's tripinfo until episode_metrics() reads it
        self._view = self._last_frame = None
        self._near = None  # (distance, every lane's vehicles within it) this decision

    def _core_config(self) -> dict:
        s, lights = self.scenario, self.network.lights
        return {
            "net_file": s.net_file, "route_files": list(s.route_files), "begin": s.begin, "end": s.end,
            "decision": s.decision_seconds, "yellow": s.yellow_seconds, "lights": [x.id for x in lights],
            "lanes": [list(x.lanes) for x in lights],
            "greens": [[x.phases[i] for i in x.greens] for x in lights],
            "controlled": [] if self.program else list(self.possible_agents), "max_distance": self.max_distance,
            **({"regions": self._region_layouts()} if self.region_data else {}),
        }

    def _region_layouts(self) -> list[dict]:
        return [asdict(region_layout(self.scenario.net_file, a)) for a in self.possible_agents]

    def region_spec(self, agent):
        """The region layout of a learner (:func:`ials_zoo.sumo_net.influence.region_spec`)."""
        return region_spec(self._check_agent(agent), **self._scenario_options)

    # -- spaces
    def observation_space(self, agent):
        return self.observation_spaces[self._check_agent(agent)]

    def action_space(self, agent):
        return self.action_spaces[self._check_agent(agent)]

    def _check_agent(self, agent):
        if agent not in self.possible_agents:
            raise BadInput(f"unknown agent {agent!r}; agents: {self.possible_agents}")
        return agent

    # -- episode
    def _light_measures(self, tls: str) -> np.ndarray:
        k = self._index[tls]
        return self._measures[self._rows[k]:self._rows[k + 1]]

    def observe(self, tls: str) -> np.ndarray:
        """Light ``tls``'s observation now (any light, learner or not)."""
        if self._observe in GREEN_OBSERVATIONS or self._observe is drq_wave:  # greens' scores: all lights at once
            return self._observations([tls])[tls]
        return self._observe(self._light_measures(tls), int(self._phases[self._index[tls]]))

    def _observations(self, agents) -> dict[str, np.ndarray]:
        """``agents``' observations now: RESCO's tables for every light in one pass, every green's
        pressure or wave in one product, else the observation function light by light."""
        if self._observe in GREEN_OBSERVATIONS:
            scores, starts = self._green_scores()
            return {a: self._observe(scores[starts[k]:starts[k + 1]], int(self._phases[k]))
                    for a, k in ((a, self._index[a]) for a in agents)}
        if self._observe is drq_wave:
            scores, starts = self._green_scores()
            return {a: drq_wave(self._light_measures(a), scores[starts[k]:starts[k + 1]], int(self._phases[k]))
                    for a, k in ((a, self._index[a]) for a in agents)}
        if self._observe not in BATCHED_OBSERVATIONS:
            return {a: self._observe(self._light_measures(a), int(self._phases[self._index[a]])) for a in agents}
        table = lanes_tables(self._measures, self._phases, self._starts, BATCHED_OBSERVATIONS[self._observe])
        rows, index = self._rows, self._index
        return {a: table[rows[index[a]]:rows[index[a] + 1]].reshape(-1) for a in agents}

    def _green_scores(self) -> tuple[np.ndarray, list[int]]:
        """Every green's pressure (``mplight``) or wave (``wave``, ``drq_wave``), and each light's first green."""
        if self._observe is mplight:
            return self._pressures.of_greens(self._measures[:, QUEUE]), self._pressures.green_starts
        return self._waves.of_greens(self.near_all(WAVE_DISTANCE)), self._waves.green_starts

    def measures(self, tls: str) -> dict[str, np.ndarray]:
        """Light ``tls``'s raw per-lane measures now (:data:`ials_zoo.sumo_net.core.MEASURES`),
        lanes in its observation order; for rule-based controllers."""
        m = self._light_measures(tls)
        return {name: m[:, i].copy() for i, name in enumerate(MEASURES)}

    def queues(self) -> np.ndarray:
        """Every light's lanes' queues now (network order, concatenated; for max pressure)."""
        return self._measures[:, QUEUE].copy()

    def near_counts(self, tls: str, distance: float) -> np.ndarray:
        """Light ``tls``'s vehicles within ``distance`` m of it, per lane (observation order),
        whatever the env's own ``max_distance``: a rule with a detection distance of its own
        (RESCO's MAXWAVE: 50 m) reads it here. One core call per decision for every light."""
        k = self._index[tls]
        return self.near_all(distance)[self._rows[k]:self._rows[k + 1]].copy()

    def near_all(self, distance: float) -> np.ndarray:
        """Every light's lanes' vehicles within ``distance`` m (network order, concatenated; kept
        for the decision: read, not written)."""
        if self._near is None or self._near[0] != distance:
            self._near = (distance, self._sim.call("near_counts", float(distance)))
        return self._near[1]

    def _core_step(self, actions: list[int]) -> tuple:
        """The core's ``step`` arguments for these actions (a local simulator adds its influence)."""
        return (actions,)

    def _store(self, result) -> None:
        if self.region_data:
            *result, self._region = result
        self._measures, self._phases, self._time = result

    def _infos(self) -> dict:
        """Every learner's region data (``region_data=True``; :mod:`ials_zoo.core.region`), else {}."""
        if not self.region_data:
            return {a: {} for a in self.agents}
        influences, dsets = self._region
        rows = self._region_rows
        return {a: {"influence": influences[rows[a]].copy(), "dset": dsets[rows[a]].copy(),
                    "dset_full": full_dset(dsets[rows[a]], self._light_measures(a))} for a in self.agents}

    def reset(self, seed=None, options=None):
        """Start an episode (``options``: none are known; PettingZoo's API)."""
        check_reset_options(options)
        seed = check_seed(seed, upper=SUMO_SEED_MAX)
        if seed is not None:
            self._seed_rng = np.random.default_rng(seed)
        else:
            seed = int(self._seed_rng.integers(SUMO_SEED_MAX + 1))
        self._episodes += 1
        self._last_seed = seed
        self._drop_unread_tripinfo()  # the last episode's, never asked for
        previous, self._metrics = self._tripinfo, None
        self._tripinfo = os.path.join(self._tmp, f"tripinfo_{self._episodes}.xml")
        if self.fresh_process:  # a new process, started during the last episode
            self._sim.restart(spare=True)
        self._store(self._sim.call("reset", seed, self._tripinfo))
        if self.program == "actuated":
            self._sim.call("make_actuated")
        self._near = None
        _remove_if_there(previous)  # an episode cut short: SUMO wrote its file until the reset above
        self.agents = list(self.possible_agents)
        return self._observations(self.agents), self._infos()

    def _actions(self, actions) -> list[int]:
        if not isinstance(actions, dict):
            raise BadInputType(f"actions must be a dict agent -> action, got {type(actions).__name__}")
        extra = [a for a in actions if a not in self.agents]
        if extra:
            raise BadInput(f"actions for unknown agent(s) {extra}; agents: {self.agents}")
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise BadInput(f"missing actions for agent(s) {missing}")
        out = []
        for a in self.agents:
            act = actions[a]
            n = self.action_spaces[a].n
            if isinstance(act, (bool, np.bool_)) or not isinstance(act, (int, np.integer)) and not (
                    isinstance(act, np.ndarray) and act.shape == () and np.issubdtype(act.dtype, np.integer)):
                raise BadInputType(f"action of {a!r} must be an int in [0, {n}), got {act!r}")
            if not 0 <= int(act) < n:
                raise BadInput(f"action of {a!r} must be in [0, {n}) (its green phases), got {int(act)}")
            out.append(int(act))
        return out

    def step(self, actions):
        if not self.agents:
            raise RuntimeError("step() called on a finished episode; call reset() first")
        actions = self._actions(actions)
        self._store(self._sim.call("step", *self._core_step([] if self.program else actions)))
        self._near = None
        done = self._time >= self.scenario.end
        obs, rewards = self._observations(self.agents), self._rewards()  # wave asks SUMO: before it ends
        if done:
            self._metrics = self._finish()
        terms = {a: False for a in self.agents}
        truncs = {a: done for a in self.agents}
        infos = self._infos()
        if done:
            self.agents = []
        return obs, rewards, terms, truncs, infos

    def _rewards(self) -> dict[str, float]:
        if self._reward is None:  # RESCO's pressure: minus every light's pressure, one product
            pressure = self._pressures.of_lights(self._measures[:, QUEUE])
            return {a: -float(pressure[self._index[a]]) for a in self.agents}
        rows, reward = self._rows, self._reward
        return {a: reward(self._measures[rows[k]:rows[k + 1]], int(self._phases[k]))
                for a, k in ((a, self._index[a]) for a in self.agents)}

    def run_uncontrolled(self, actuated: bool = False, on_decision=None) -> dict[str, float]:
        """Run the episode started by :meth:`reset` to its end with no learner acting (every
        light on its own program; ``actuated``: on SUMO's actuated control of the program's
        phases); ``on_decision(env)`` is called after each decision (read :meth:`measures`
        there); returns :meth:`episode_metrics`."""
        if self.possible_agents:
            raise BadInput("run_uncontrolled() needs learners=[] (every light on its own program)")
        if self._measures is None or self._metrics is not None:
            raise RuntimeError("run_uncontrolled() needs a fresh reset()")
        if actuated:
            self._sim.call("make_actuated")
        while self._time < self.scenario.end:
            self._store(self._sim.call("step", []))
            if on_decision is not None:
                on_decision(self)
        self._metrics = self._finish()
        return self.episode_metrics()

    def _finish(self) -> dict[str, float]:
        """End the episode in SUMO; its tripinfo is read when :meth:`episode_metrics` asks (a
        training loop never does, and reading it costs about 1-3% of a small map's episode)."""
        self._unread_tripinfo = self._tripinfo
        return self._sim.call("finish")

    def _read_tripinfo(self) -> None:
        """Add the tripinfo's metrics (RESCO's delay, ...) to the episode's; the file is removed
        once read (a long run keeps no episode's file), and kept for another try if reading fails."""
        path, s = self._unread_tripinfo, self.scenario
        if not os.path.exists(path):
            raise RuntimeError(f"the episode's tripinfo {path} is gone: call episode_metrics() before close()")
        self._metrics.update(episode_metrics(path, s.route_files, s.end, self._schedule))
        self._drop_unread_tripinfo()

    def _drop_unread_tripinfo(self) -> None:
        path, self._unread_tripinfo = getattr(self, "_unread_tripinfo", None), None
        _remove_if_there(path)

    # -- extras
    def state(self) -> np.ndarray:
        """Every light's observation, concatenated in network order (float32)."""
        if self._measures is None:
            raise RuntimeError("state() before reset()")
        obs = self._observations(self.network.ids)
        return np.concatenate([obs[x] for x in self.network.ids]).astype(np.float32)

    def enable_metrics(self) -> None:
        """Metrics are always recorded (SUMO's tripinfo of every episode); kept for the domain contract."""

    def episode_metrics(self) -> dict[str, float]:
        """The metrics of the episode that just ended (see the class docstring)."""
        if self._metrics is None:
            raise RuntimeError("episode_metrics() before the end of an episode")
        if self._unread_tripinfo is not None:
            self._read_tripinfo()
        return dict(self._metrics)

    @property
    def sim_time(self) -> float:
        """SUMO's clock (s)."""
        return self._time

    def sumo_query(self, domain: str, method: str, *args):
        """Call a libsumo getter on this env's simulation, e.g. ``("lane", "getLength", id)``."""
        return self._sim.call("query", domain, method, *args)

    def render(self):
        if self.render_mode is None or self._measures is None:
            return None
        if self.render_mode == "rgb_array":
            if self._view is None:
                self._view = NetworkView(self.network)
            if self._metrics is not None:  # the episode is over and SUMO closed: the last picture
                return self._last_frame if self._last_frame is not None else np.asarray(self._view.base)
            self._last_frame = self._view.draw(self._sim.call("render_data"), self.possible_agents)
            return self._last_frame
        lines = [f"t={self._time:.0f} s"]
        for x in self.network.ids:
            q = int(self._light_measures(x)[:, 2].sum())
            mark = "*" if x in self.possible_agents else " "
            lines.append(f"{mark}{x[:40]:<40} phase {int(self._phases[self._index[x]]):>2d} queue {q:>3d}")
        text = "\n".join(lines)
        if self.render_mode == "human":
            print(text, flush=True)
            return None
        return text

    def close(self):
        sim = getattr(self, "_sim", None)
        if sim is not None:
            sim.close()
        tmp = getattr(self, "_tmp", None)
        if tmp:
            shutil.rmtree(tmp, ignore_errors=True)
            self._tmp = None
        self.agents = []

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def _remove_if_there(path: str | None) -> None:
    if path is not None:
        with contextlib.suppress(FileNotFoundError):
            os.remove(path)


def raw_env(**options):
    """The AEC version without wrappers (PettingZoo's ``raw_env`` convention)."""
    return parallel_to_aec_wrapper(SumoNetEnv(**options))


def parallel_env(**options) -> SumoNetEnv:
    """``sumo_net_v0`` as a PettingZoo ``ParallelEnv``."""
    return SumoNetEnv(**options)


def env(**options):
    """``sumo_net_v0`` as a PettingZoo AEC env (via ``parallel_to_aec``)."""
    return parallel_to_aec(parallel_env(**options))
