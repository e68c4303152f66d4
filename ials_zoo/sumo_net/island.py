"""The local simulator of a ``sumo_net_v0`` junction: its region alone, fed influence sources.

:class:`SumoNetLocalSimulator` cuts the light's region from the network
(:mod:`ials_zoo.sumo_net.regions`) ``n_envs`` times into one SUMO simulation (ids prefixed
``"c<copy>~"``, :func:`~ials_zoo.sumo_net.regions.region_prefix`) and runs RESCO's signal loop on it (:class:`~ials_zoo.sumo_net.core.NetCore`):
the same spaces, observation and reward as the GS's light.

Each decision it is given the influence sources of :mod:`ials_zoo.sumo_net.influence`: per
entry point and second, how many vehicles come in (0, 1, 2). Each one is a vehicle the GS
itself let in at that entry point, drawn at random from a recording of the GS (every light on
its own program, the map's hour, SUMO seed 0; :func:`entry_tables`, cached under
``$IALS_ZOO_CACHE/sumo_net``, or ``~/.cache/ials_zoo/sumo_net``): its route inside the region, lane, position, type and speed
factor, inserted at the highest safe speed. A vehicle that cannot be inserted within
:data:`INSERT_PATIENCE` seconds is dropped, as the GS's could not have entered then. Vehicles
leave a few metres into the region's outgoing edges (:attr:`~ials_zoo.sumo_net.regions.NetRegion.exits`).
What happens beyond an exit is an influence source too: for a decision it says the exit is
blocked, that road's lanes are held at :data:`BLOCKED_SPEED`, so the vehicles reaching it halt and the queue
spills back into the region as behind a jam in the GS; the d-set reads such an exit as blocked now, as
the GS reads the queue of a jam in the exit's first metres. An exit blocked :data:`GRIDLOCK_DECISIONS`
decisions in a row stays blocked to the episode's end, whatever the AIP draws: the GS runs SUMO without
teleports, so a gridlock past an exit never clears: in the GS on ingolstadt21 a block that had lasted
that long ended at 16 of 5,464 decisions (``docs/sumo_net.md``, "jams"). An AIP reading the block's
history learns most of that from the GS, but still let a drawn block go now and then; a gridlock does not.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from dataclasses import asdict
from pathlib import Path

import numpy as np
from gymnasium import spaces

from ials_zoo.core.local import LocalSimulator, agent_list, check_n_envs
from ials_zoo.core.streams import agent_key
from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.influence.constant import MarginalPredictor
from ials_zoo.sumo.command import load_budget
from ials_zoo.sumo.lease import SimHandle
from ials_zoo.sumo_net.core import NetCore
from ials_zoo.sumo_net.influence import (
    ENTRY_CLASSES,
    EntryWatcher,
    RegionLayout,
    full_dset,
    region_layout,
    region_spec,
)
from ials_zoo.sumo_net.local import record_influence
from ials_zoo.sumo_net.mdp import N_FEATURES, observation_fn, reward_fn
from ials_zoo.sumo_net.names import SCENARIO_OPTIONS
from ials_zoo.sumo_net.network import read_network
from ials_zoo.sumo_net.regions import CHAIN_CAP_METRES, EXIT_METRES, REACH_METRES, region_prefix, regions_of
from ials_zoo.sumo_net.replay import cut_regions, vehicle_types
from ials_zoo.sumo_net.scenario import scenario_of
from ials_zoo.utils import check_seed, parse_untrusted_json_object

MAX_TABLE_BYTES = 64 << 20
SUMO_SEEDS = 2**31 - 1
INSERT_PATIENCE = 2  # seconds a vehicle that could not enter at once may wait (then it is dropped)
BLOCKED_SPEED = 0.01  # m/s: a blocked exit's speed limit (below SUMO's halting speed, 0.1)
GRIDLOCK_DECISIONS = 10  # an exit blocked this many decisions in a row stays blocked (module docstring)


def _table_path(scenario, light: str, seconds: int, seed: int) -> Path:
    root = os.environ.get("IALS_ZOO_CACHE")

    key = json.dumps([scenario.name, os.path.getsize(scenario.net_file), scenario.begin, light, seconds, seed,
                      CHAIN_CAP_METRES, EXIT_METRES, REACH_METRES])
    h = hashlib.sha256(key.encode()).hexdigest()[:12]
    return (Path(root) if root else Path.home() / ".cache" / "ials_zoo") / "sumo_net" / f"entries_{h}.json"


def entry_tables(scenario, lights, seconds: int | None = None, seed: int = 0) -> dict[str, list]:
    """Per light, per entry point of its region (:attr:`RegionLayout.points`), the GS's entries
    there ``[edges inside, lane index, position, type, speed factor]`` over ``seconds`` of the
    GS (default: the scenario's) with every light on its own program. Cached as JSON, one file
    per light; the missing lights are recorded in one GS run."""
    return {light: x["tables"] for light, x in _recorded(scenario, lights, seconds, seed).items()}


def entry_histograms(scenario, lights, seconds: int | None = None, seed: int = 0) -> dict[str, list]:
    """Per light, per entry point: the seconds of the same recording in which 0, 1, or 2 or more
    vehicles came in there."""
    return {light: x["histogram"] for light, x in _recorded(scenario, lights, seconds, seed).items()}


def _recorded(scenario, lights, seconds, seed: int) -> dict[str, dict]:
    seconds = int(seconds or scenario.end - scenario.begin)
    out = {light: _cached(_table_path(scenario, light, seconds, seed)) for light in lights}
    missing = [light for light, x in out.items() if x is None]
    if missing:
        for light, x in _record_tables(scenario, missing, seconds, seed).items():
            path = _table_path(scenario, light, seconds, seed)
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_text(json.dumps({"light": light, "seconds": seconds, "seed": seed, **x}))
            os.replace(tmp, path)  # never half-written
            out[light] = x
    return out


def _cached(path: Path) -> dict | None:
    if not path.is_file() or path.stat().st_size > MAX_TABLE_BYTES:
        return None
    data = parse_untrusted_json_object(path.read_bytes(), f"entry table {path}")
    if not (isinstance(data.get("tables"), list) and isinstance(data.get("histogram"), list)):
        return None  # an older cache file: recorded again
    return {"tables": data["tables"], "histogram": data["histogram"]}


def _record_tables(scenario, lights: list, seconds: int, seed: int) -> dict[str, dict]:
    regions = {light: regions_of(scenario.net_file)[light] for light in lights}
    point = {light: {e: j for j, e in enumerate(r.sources)} for light, r in regions.items()}
    tables = {light: [[] for _ in range(len(r.sources) + 1)] for light, r in regions.items()}
    histogram = {light: np.zeros((len(r.sources) + 1, ENTRY_CLASSES), np.int64) for light, r in regions.items()}
    for step in record_influence(scenario, regions, seconds, seed):
        counts = {light: np.zeros(len(r.sources) + 1, np.int64) for light, r in regions.items()}
        for light, _vehicle, edges, lane, pos, _speed, vtype, factor in step:
            j = point[light].get(edges[0], len(point[light]))
            tables[light][j].append([list(edges), lane, pos, vtype, factor])
            counts[light][j] += 1
        for light, c in counts.items():
            histogram[light][np.arange(len(c)), np.minimum(c, ENTRY_CLASSES - 1)] += 1
    return {light: {"tables": tables[light], "histogram": histogram[light].tolist()} for light in lights}


def gs_marginal_predictors(lights, record_seconds: int | None = None, record_seed: int = 0, **options) -> dict:
    """Per light, an AIP that needs no training: every entry source drawn from the GS's own
    frequency of 0, 1 and 2+ entering vehicles per second at that entry point
    (:func:`entry_histograms`; a :class:`~ials_zoo.influence.constant.MarginalPredictor`), every
    exit free. Costs what a trained MLP costs to within a call, so the benchmark uses it."""

    scenario_options = _scenario_options(options)
    scenario = scenario_of(**scenario_options)
    out = {}
    for light, hist in entry_histograms(scenario, list(lights), record_seconds, record_seed).items():
        region = region_spec(light, **scenario_options)
        per_point = [(np.asarray(h, np.float64) + 0.5) / (np.sum(h) + 0.5 * ENTRY_CLASSES) for h in hist]
        free = np.array([1.0, 0.0])  # the recording counts entries only: every exit stays free
        exits = sum(n.startswith("exit:") for n in region.influence_names)
        probs = [p for _ in range(scenario.decision_seconds) for p in per_point] + [free] * exits
        out[light] = MarginalPredictor(region, probs, metadata={"from": "the GS's entries per second"})
    return out


class IslandCore(NetCore):
    """:class:`~ials_zoo.sumo_net.core.NetCore` on the cut copies, inserting each second the
    vehicles the influence sources name, drawn from each copy's entry tables."""

    def __init__(self, layouts: list, tables: list, row_keys: list, prefixes: list, watch: bool = False, **config):
        super().__init__(**config)
        self.routes: dict[tuple, str] = {}  # (row, edges) -> a route added once per simulation
        self.layouts = [RegionLayout(**x) for x in layouts]
        self.exits = [dict(x.exits) for x in self.layouts]  # per row: edge -> where its vehicles leave
        self.tables = tables  # per row, per entry point
        self.row_keys = [(str(a), int(j)) for a, j in row_keys]  # (light, copy): each row's own random stream
        self.prefixes = list(prefixes)
        self.watcher = EntryWatcher(self.layouts, self.decision)
        self.watch = bool(watch)  # measure what entered every second (costs a call per edge and second)
        self.plan = self._no_plan()
        self.second = 0
        self.rngs = []
        self.inserted = 0
        self.waiting: list[tuple[str, int]] = []  # our vehicles not inserted yet, with their wait (s)
        self.due: dict[int, list] = {}
        self.exit_lanes: list | None = None  # per row, per exit: its lanes and their own speed limits
        self.blocking = [np.zeros(len(x.exits), np.int64) for x in self.layouts]
        self.entry_sources = [self.decision * len(x.points) for x in self.layouts]  # per row, before its exits

    def reset(self, seed: int, tripinfo: str | None = None):
        self.rngs = [np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(agent_key(a), j)))
                     for a, j in self.row_keys]
        self.watcher.reset()
        self.waiting, self.plan, self.second, self.routes, self.due = [], self._no_plan(), 0, {}, {}
        self.inserted = 0  # vehicle names depend on the episode alone (SUMO orders some work by them)
        for b in self.blocking:
            b[:] = 0  # a new simulation: every road at its own speed limit
        result = super().reset(seed % SUMO_SEEDS, None)  # SUMO's seeds are 31-bit
        if self.exit_lanes is None:
            raw = self.ls._libsumo
            self.exit_lanes = [[[(f"{e}_{i}", raw.lane_getMaxSpeed(f"{e}_{i}")) for i in range(raw.edge_getLaneNumber(e))]
                                for e in x.exit_edges] for x in self.layouts]
        return self._with_region(result)

    def step(self, actions, influences=None):
        sizes = self.entry_sources
        self.plan = [np.array(u, np.int64) for u in influences]  # per row: every second's entries, then exits
        for plan, held, n in zip(self.plan, self.watcher.held, sizes):
            plan[n:][held >= GRIDLOCK_DECISIONS] = 1  # a gridlock past the exit: it never clears (module docstring)
        self.due = {}  # second -> [(row, entry point, vehicles)]: only what comes in
        for r, (plan, layout, n) in enumerate(zip(self.plan, self.layouts, sizes)):
            entries = plan[:n].reshape(self.decision, len(layout.points))
            for second, j in zip(*np.nonzero(entries)):
                self.due.setdefault(int(second), []).append((r, int(j), int(entries[second, j])))
        self._block_exits(self.ls._libsumo, [plan[n:] for plan, n in zip(self.plan, sizes)])
        self.watcher.start_decision()
        self.second = 0
        return self._with_region(super().step(actions))

    def _no_plan(self) -> list:
        return [np.zeros(self.decision * len(x.points) + len(x.exits), np.int64) for x in self.layouts]

    def _with_region(self, result):
        """The core's result and the region data: what entered (measured if watched, else what
        the sources said) and the d-sets (the exits' blocks measured as in the GS)."""
        raw = self.ls._libsumo
        if not self.watch:
            self.watcher.measure_exits(raw)
        for now, plan, n in zip(self.watcher.blocked_now, self.plan, self.entry_sources):
            # an exit given blocked is a queue from beyond the region that reaches its first metres, as
            # the GS measures a block, even before a vehicle of the region halts there
            now |= (plan[n:] > 0).astype(now.dtype)
        told = self.watcher.influences() if self.watch else [p.copy() for p in self.plan]
        self.watcher.end_decision(self.plan)  # the blocks the sources gave: the GS's are its measured ones
        return (*result, (told, self.watcher.dsets(raw)))

    def _block_exits(self, raw, exits: list) -> None:
        """Each exit as its source says for this decision: blocked, its lanes' speed limit
        :data:`BLOCKED_SPEED` (a vehicle reaching it halts and the queue backs up, as behind
        a jam in the GS), or free at its own limit. A call only where a state changes."""
        for r, want in enumerate(exits):
            for k in np.nonzero(want != self.blocking[r])[0]:
                for lane, limit in self.exit_lanes[r][k]:
                    raw.lane_setMaxSpeed(lane, BLOCKED_SPEED if want[k] else limit)
            self.blocking[r][:] = want

    def _insert(self, raw, second: int) -> list[str]:
        names = []
        for r, j, count in self.due.get(second, ()):
            table, prefix = self.tables[r][j], self.prefixes[r]
            for _ in range(count if table else 0):
                edges, lane, pos, vtype, factor = table[int(self.rngs[r].integers(len(table)))]
                self.inserted += 1
                name = f"{prefix}{self.inserted}"
                key = (r, tuple(edges))
                if key not in self.routes:
                    self.routes[key] = f"{prefix}r{len(self.routes)}"
                    raw.route_add(self.routes[key], [prefix + e for e in edges])
                leave = self.exits[r].get(prefix + edges[-1])
                raw.vehicle_add(name, self.routes[key], vtype, "now", str(lane), str(max(pos, 0.0)), "max", "current",
                                "max" if leave is None else str(leave))
                raw.vehicle_setSpeedFactor(name, factor)
                names.append(name)
        return names

    def _advance(self, seconds: int) -> None:
        raw = self.ls._libsumo
        for _ in range(seconds):
            self.waiting += [(name, 0) for name in self._insert(raw, min(self.second, self.decision - 1))]
            super()._advance(1)
            self.second += 1
            if self.waiting:
                self._drop_late(raw)
            if self.watch:
                self.watcher.after_step(raw)

    def _drop_late(self, raw) -> None:
        """A vehicle that could not be inserted gets :data:`INSERT_PATIENCE` more seconds (the
        GS did let it in, a moment's difference in the region may block its spot), then it is
        dropped: the GS would not have let it in so late."""
        pending = set(raw.simulation_getPendingVehicles())
        still = []
        for name, age in self.waiting:
            if name not in pending:
                continue
            if age >= INSERT_PATIENCE:
                raw.vehicle_remove(name, 0)
            else:
                still.append((name, age + 1))
        self.waiting = still


def _scenario_options(options: dict) -> dict:
    return {k: v for k, v in options.items() if k in SCENARIO_OPTIONS}


class SumoNetLocalSimulator(LocalSimulator):
    """``n_envs`` copies of each of ``agents``' regions (module docstring); agents must share
    their spaces (the rows stack), so in practice one light.

    Args:
        agents: light id(s).
        n_envs: copies per light.
        backend: the lease's (``"auto"``: in this process if it holds no simulation).
        record_seconds, record_seed: the GS recording the entry tables come from.
        observation, reward, max_distance: as the GS's.
        **options: ``sumo_net_v0``'s scenario options (``net=``, ...); GS-only options are ignored.

    Attributes:
        last_entries: per row, the vehicles that actually entered in the last decision, as
            influence classes (``measure_entries=True``: measured like the GS's, a call per
            edge and second; else None).
    """

    supports_step_single = False

    def __init__(self, agents, n_envs: int = 1, backend: str = "auto", record_seconds: int | None = None,
                 record_seed: int = 0, observation: str = "drq_norm", reward: str = "wait_norm",
                 max_distance: float = 200.0, measure_entries: bool = False, **options):

        self.scenario = scenario_of(**_scenario_options(options))
        self.n_envs = check_n_envs(n_envs)
        lights = {x.id: x for x in read_network(self.scenario.net_file).lights}
        self.agents = agent_list(agents)
        unknown = [a for a in self.agents if a not in lights]
        if unknown:
            raise BadInput(f"unknown agent(s) {unknown}: not traffic lights of {self.scenario.name}")
        sizes = {(len(lights[a].lanes), lights[a].n_actions) for a in self.agents}
        if len(sizes) > 1:
            raise BadInput(f"lights with their own spaces cannot share one local simulator: {list(self.agents)}")
        first = lights[self.agents[0]]
        self.observation_space = spaces.Box(0.0, np.inf, (N_FEATURES * len(first.lanes),), np.float32)
        self.action_space = spaces.Discrete(first.n_actions)
        self.max_cycles = self.scenario.decisions
        self.regions = tuple(region_spec(a, **_scenario_options(options)) for a in self.agents)
        self._observe, self._reward = observation_fn(observation), reward_fn(reward)
        if not isinstance(measure_entries, (bool, np.bool_)):
            raise BadInputType(f"measure_entries must be a bool, got {measure_entries!r}")
        self._measure = bool(measure_entries)
        self._folder = Path(tempfile.mkdtemp(prefix="ials_zoo_island_"))
        try:
            config = self._config(lights, record_seconds, record_seed, float(max_distance))
            s = self.scenario
            self._sim = SimHandle("ials_zoo.sumo_net.island:IslandCore", config, backend,
                                  load_seconds=load_budget(s.net_file, *s.route_files))
        except BaseException:
            shutil.rmtree(self._folder, ignore_errors=True)
            raise
        self.last_entries = None
        self._measures = None

    def _config(self, lights: dict, record_seconds, record_seed: int, max_distance: float) -> dict:
        s, rows = self.scenario, self.copy_agents()
        regions = regions_of(s.net_file)
        merged = cut_regions(s.net_file, {f"c{r}": regions[a] for r, a in enumerate(rows)}, self._folder)
        vtypes = vehicle_types(s.route_files, self._folder / "vtypes.add.xml")
        tables = entry_tables(s, self.agents, record_seconds, record_seed)
        layouts = [region_layout(s.net_file, a).prefixed(region_prefix(f"c{r}")) for r, a in enumerate(rows)]
        return {"net_file": str(merged), "route_files": [], "begin": s.begin, "end": s.end,
                "decision": s.decision_seconds, "yellow": s.yellow_seconds, "max_distance": max_distance,
                "extra": ["--additional-files", str(vtypes)], "lights": [x.light for x in layouts],
                "lanes": [list(x.lanes) for x in layouts], "controlled": [x.light for x in layouts],
                "greens": [[lights[a].phases[i] for i in lights[a].greens] for a in rows],
                "layouts": [asdict(x) for x in layouts], "tables": [tables[a] for a in rows],
                "row_keys": [(a, r % self.n_envs) for r, a in enumerate(rows)],
                "prefixes": [region_prefix(f"c{r}") for r in range(len(rows))], "watch": self._measure}

    def _outputs(self, result):
        measures, phases, _time, (influences, dsets) = result
        n = self.observation_space.shape[0] // N_FEATURES  # lanes per light: the rows share their spaces
        obs, rewards, full = [], [], []
        for r in range(self.n_copies):
            m = measures[r * n:(r + 1) * n]
            obs.append(self._observe(m, int(phases[r])))
            rewards.append(self._reward(m, int(phases[r])))
            full.append(full_dset(dsets[r], m))
        self.last_entries = np.stack(influences) if self._measure else None
        return (np.stack(obs), np.asarray(rewards, np.float64),
                {"dset": np.stack(dsets).astype(np.uint8), "full": np.stack(full).astype(np.uint8)})

    def reset(self, seed: int | None = None):
        seed = check_seed(seed)
        if seed is None:
            seed = int(np.random.SeedSequence().generate_state(1)[0] >> 1)
        obs, _, dsets = self._outputs(self._sim.call("reset", int(seed), None))
        return obs, dsets

    def step(self, actions, influences):
        actions = np.asarray(actions).reshape(-1)
        influences = np.asarray(influences)
        if actions.shape != (self.n_copies,):
            raise BadInputType(f"actions must have shape ({self.n_copies},), got {actions.shape}")
        if influences.shape != (self.n_copies, self.regions[0].n_sources):
            raise BadInputType(f"influences must have shape ({self.n_copies}, {self.regions[0].n_sources}), "
                               f"got {influences.shape}")
        return self._outputs(self._sim.call("step", [int(a) for a in actions], influences.tolist()))

    def close(self) -> None:
        sim = getattr(self, "_sim", None)
        if sim is not None:
            sim.close()
            self._sim = None
        folder = getattr(self, "_folder", None)
        if folder is not None:
            shutil.rmtree(folder, ignore_errors=True)
            self._folder = None


def local_simulator(agents, n_envs: int = 1, **options) -> SumoNetLocalSimulator:
    """The domain's factory: GS-only options (``learners``, ``fresh_process``, ...) are ignored."""
    keep = {"backend", "record_seconds", "record_seed", "observation", "reward", "max_distance", "measure_entries",
            *SCENARIO_OPTIONS}
    return SumoNetLocalSimulator(agents, n_envs, **{k: v for k, v in options.items() if k in keep})


__all__ = ["IslandCore", "SumoNetLocalSimulator", "entry_histograms", "entry_tables", "gs_marginal_predictors",
           "local_simulator"]
