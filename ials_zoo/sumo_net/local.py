"""Local simulators of every light's region of a ``sumo_net_v0`` network, with RESCO's MDP: a
first multi-agent IALS of a real network, to measure what it costs against the GS.

Every region (:mod:`ials_zoo.sumo_net.regions`) is cut from the network and all of them run side
by side in one SUMO simulation (ids prefixed ``"<light>~"``); :class:`LocalNetEnv` is
``sumo_net_v0``'s ParallelEnv on it: the same agents, spaces, signal loop, observations and
rewards (:class:`ials_zoo.sumo_net.core.NetCore`), each light acting on its own region.

**Influence** (first version, no AIP yet): drawn from the GS's own statistics. One GS run with
every light on its own program is recorded (:meth:`ials_zoo.sumo_net.replay.ReplayCore.record`:
every vehicle entering a region, where and as it entered, with the rest of its route inside);
then every SUMO step, for every region, the arrivals of one recorded step drawn at random are
inserted (:class:`GSInfluence`). This keeps each step's joint arrivals and the regions' mean
inflow; it forgets the timing of arrivals across steps (platoons after a green upstream) and
their dependence on the learners' actions, which is what an AIP is for. Lights of other regions
that a cut keeps (a junction just past a short exit) run their own program.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.sumo.command import load_budget
from ials_zoo.sumo.lease import SimHandle
from ials_zoo.sumo_net.core import NetCore
from ials_zoo.sumo_net.env import SumoNetEnv
from ials_zoo.sumo_net.names import SCENARIO_OPTIONS
from ials_zoo.sumo_net.network import read_network
from ials_zoo.sumo_net.regions import region_prefix, regions_of
from ials_zoo.sumo_net.replay import ReplayCore, cut_regions, vehicle_types
from ials_zoo.sumo_net.scenario import scenario_of


def record_influence(scenario, regions: dict, seconds: int, seed: int = 0) -> list:
    """Every region's entries at every step of ``seconds`` of the GS (own programs, SUMO seed
    ``seed``), as :meth:`~ials_zoo.sumo_net.replay.ReplayCore.record` gives them."""
    sim = SimHandle("ials_zoo.sumo_net.replay:ReplayCore", {}, "auto", timeout=3600.0, loads=ReplayCore.LOADS,
                    load_seconds=load_budget(scenario.net_file, *scenario.route_files))
    try:
        edges = {light: r.edges for light, r in regions.items()}
        offsets = {light: {e: o for e, o in zip(r.sources, r.entry_offsets) if o > 0} for light, r in regions.items()}
        entries, _, _ = sim.call("record", scenario.net_file, scenario.route_files, scenario.begin, seconds,
                                 edges, [], [], seconds + 1, seed, offsets)
    finally:
        sim.close()
    return entries


class GSInfluence:
    """Per light, the recorded steps' arrivals ``(vehicle, edges inside, lane index, position,
    speed, type, speed factor)``, one list per recorded step (module docstring)."""

    def __init__(self, entries_per_step: list, lights):
        self.recorded = len(entries_per_step)
        self.steps = {light: [[] for _ in entries_per_step] for light in lights}
        for t, step in enumerate(entries_per_step):
            for light, *entry in step:
                if light in self.steps:
                    self.steps[light][t].append(tuple(entry))

    def rate(self) -> float:
        """Mean vehicles entering all regions per step."""
        return sum(len(x) for steps in self.steps.values() for x in steps) / max(self.recorded, 1)


class LocalNetCore(NetCore):
    """:class:`~ials_zoo.sumo_net.core.NetCore` on the regions' network, inserting each step
    ``influence`` (``light -> recorded steps' arrivals``) drawn with the episode's seed."""

    def __init__(self, influence: dict, **config):
        super().__init__(**config)
        self.influence = {light: steps for light, steps in influence.items() if steps}
        self.rng = np.random.default_rng(0)
        self.inserted = 0

    def reset(self, seed: int, tripinfo: str | None = None):
        self.rng = np.random.default_rng(seed)
        return super().reset(seed, None)  # no trips to score: a region's vehicles are borrowed

    def _insert(self) -> None:
        raw = self.ls._libsumo
        for light, steps in self.influence.items():
            for vehicle, edges, lane, pos, _speed, vtype, factor in steps[int(self.rng.integers(len(steps)))]:
                self.inserted += 1
                name = f"{region_prefix(light)}{vehicle}__{self.inserted}"
                raw.route_add(name, [region_prefix(light) + e for e in edges])
                raw.vehicle_add(name, name, vtype, "now", str(lane), str(max(pos, 0.0)), "max")
                raw.vehicle_setSpeedFactor(name, factor)

    def inserted_total(self) -> int:
        """Vehicles inserted since the core was made."""
        return self.inserted

    def _advance(self, seconds: int) -> None:
        step = self.ls._libsumo.simulation_step
        for _ in range(seconds):
            self._insert()
            start = time.perf_counter()
            step(0.0)
            self.sim_seconds += time.perf_counter() - start


class RegionsNetEnv(SumoNetEnv):
    """``sumo_net_v0`` on every light's region, all side by side in one SUMO simulation (ids
    prefixed ``"<light>~"``): the GS's agents, spaces, signal loop, observations and rewards. A
    subclass says how vehicles come in: what it records before SUMO starts (:meth:`_prepare`)
    and its core. ``episode_metrics()`` has only ``queue``: trip delays need the whole network."""

    NETWORK_WIDE = False  # a region holds no other light's downstream queues: per-light observations only
    CUT = True  # the regions are cut from the network for SUMO (a core on arrays needs no cut)

    def __init__(self, **options):
        if options.get("scripted_learners", False) is not False:  # the single-agent scoring passes False
            raise BadInput("the regions' learners are driven by actions: scripted_learners must stay False")
        scenario = scenario_of(**{k: options[k] for k in SCENARIO_OPTIONS if k in options})
        self._folder = Path(tempfile.mkdtemp(prefix="ials_zoo_regions_"))
        try:
            agents = set(read_network(scenario.net_file).ids)  # a light of one green is no agent: no region
            self.regions = {k: r for k, r in regions_of(scenario.net_file).items() if k in agents}
            if self.CUT:
                self._merged = cut_regions(scenario.net_file, self.regions, self._folder)
                self._vtypes = vehicle_types(scenario.route_files, self._folder / "vtypes.add.xml")
            self._prepare(scenario)
            super().__init__(**options)
        except BaseException:
            shutil.rmtree(self._folder, ignore_errors=True)
            raise

    def _prepare(self, scenario) -> None:
        """What the core's influence needs, made before SUMO starts."""

    def _core_config(self) -> dict:
        config = super()._core_config()
        config.pop("regions", None)  # the GS's watched regions: these regions are the simulation
        ids = config["lights"]
        config.update(net_file=str(self._merged), route_files=[], extra=["--additional-files", str(self._vtypes)],
                      lights=[region_prefix(x) + x for x in ids], controlled=[region_prefix(x) + x for x in config["controlled"]],
                      lanes=[[region_prefix(x) + lane for lane in lanes] for x, lanes in zip(ids, config["lanes"])])
        return config

    def _finish(self) -> dict[str, float]:
        return self._sim.call("finish")

    def close(self):
        super().close()
        folder = getattr(self, "_folder", None)
        if folder is not None:
            shutil.rmtree(folder, ignore_errors=True)
            self._folder = None


class LocalNetEnv(RegionsNetEnv):
    """``sumo_net_v0`` on the local simulators of every light's region (module docstring).

    Takes ``sumo_net_v0``'s options (``net=``, ``learners=``, ...); ``record_seconds`` (default:
    the map's episode) is how much GS is recorded for the influence, ``record_seed`` its SUMO
    seed. ``episode_metrics()`` has only ``queue``: trip delays need the whole network.
    """

    CORE = "ials_zoo.sumo_net.local:LocalNetCore"

    def __init__(self, record_seconds: int | None = None, record_seed: int = 0, **options):
        self._record = (record_seconds, record_seed)
        super().__init__(**options)

    def _prepare(self, scenario) -> None:
        record_seconds, record_seed = self._record
        seconds = int(record_seconds or scenario.end - scenario.begin)
        self.influence = GSInfluence(record_influence(scenario, self.regions, seconds, record_seed),
                                     list(self.regions))

    def _core_config(self) -> dict:
        return {**super()._core_config(), "influence": self.influence.steps}


__all__ = ["GSInfluence", "LocalNetCore", "LocalNetEnv", "RegionsNetEnv", "record_influence"]
