"""The multi-agent IALS of a ``sumo_net_v0`` network: every light's local simulator and AIP,
one PettingZoo ParallelEnv.

Every light's region (:mod:`ials_zoo.sumo_net.regions`) is cut from the network and all of
them run side by side in one SUMO simulation (ids prefixed ``"<light>~"``; a road in two
regions is simulated in each). Each decision, every light's AIP samples its region's influence
sources (:mod:`ials_zoo.sumo_net.influence`: vehicles entering per entry point and second)
from its d-set history, and :class:`~ials_zoo.sumo_net.island.IslandCore` inserts them, each
one a vehicle the GS let in there (:func:`~ials_zoo.sumo_net.island.entry_tables`). The agents,
spaces, signal loop, observations and rewards are the GS's (:class:`IALSNetEnv` is a
:class:`~ials_zoo.sumo_net.env.SumoNetEnv` on another core). Lights that do not learn run
their own program, their regions fed by their AIPs too.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np

from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.influence.files import load_predictor_set
from ials_zoo.sumo.lease import PlainHandle
from ials_zoo.sumo_net.env import SumoNetEnv
from ials_zoo.sumo_net.influence import region_layout
from ials_zoo.sumo_net.island import entry_tables
from ials_zoo.sumo_net.local import RegionsNetEnv
from ials_zoo.sumo_net.names import ENV_ID, SCENARIO_OPTIONS
from ials_zoo.sumo_net.regions import region_prefix


def resolve_predictors(predictors, lights: list[str], options: dict) -> dict:
    """Every light's AIP: ``predictors`` is an AIP set file (``ials-zoo train-aip --agent all``),
    one spec for every light (``"uniform"``, ``"untrained"``), or a dict ``{light: predictor
    object, file or spec}``."""
    from ials_zoo.influence.ials import resolve_predictor

    if isinstance(predictors, (str, Path)) and Path(predictors).is_file():
        predictors = load_predictor_set(predictors, ENV_ID)
    if not isinstance(predictors, dict):
        predictors = {x: predictors for x in lights}
    unknown = sorted(set(predictors) - set(lights))
    missing = [x for x in lights if x not in predictors]
    if unknown or missing:
        raise BadInput(f"predictors: need exactly one per light; unknown {unknown[:3]}, missing {missing[:3]}")
    return {x: resolve_predictor(predictors[x], ENV_ID, x, options=options) for x in lights}


class IALSNetEnv(RegionsNetEnv):
    """``sumo_net_v0`` on every light's local simulator and AIP (module docstring).

    Takes ``sumo_net_v0``'s options (``net=``, ``learners=``, ...) and ``predictors`` (an AIP
    set file, see :func:`resolve_predictors`; default ``"untrained"``), ``record_seconds`` /
    ``record_seed`` (the GS recording the entering vehicles are drawn from). Defaults to one
    simulation for the whole episode series (``fresh_process=False``: no route file is replayed),
    in this process if no other simulation holds it (``backend="auto"``), else in a worker.
    ``infos[agent]`` holds the influence sources its AIP sampled and its d-sets. ``local``: the
    regions' simulator, ``"sumo"`` (cut from the network, side by side in one SUMO simulation)
    or ``"arrays"`` (:mod:`ials_zoo.sumo_net.arrays`: no SUMO, every region as numpy arrays, in
    this process).
    ``episode_metrics()`` has only ``queue``: trip delays need the whole network.
    """

    CORE = REGION_CORE = "ials_zoo.sumo_net.island:IslandCore"
    LOCAL_CORES = {"sumo": "ials_zoo.sumo_net.island:IslandCore", "arrays": "ials_zoo.sumo_net.arrays_core:ArrayNetCore"}

    def __init__(self, predictors="untrained", record_seconds: int | None = None, record_seed: int = 0,
                 fresh_process: bool = False, backend: str = "auto", local: str = "sumo", **options):
        if options.get("region_data") is not None:
            raise BadInputType("region_data: the IALS always reports its region data")
        if local not in self.LOCAL_CORES:
            raise BadInput(f"local: expected one of {', '.join(self.LOCAL_CORES)}, got {local!r}")
        self.local = local
        if local == "arrays":  # no SUMO: the regions need no cut, and the core runs in this process
            self.CORE = self.REGION_CORE = self.LOCAL_CORES[local]
            self.CUT, self.HANDLE = False, PlainHandle
        self._aips = (predictors, {k: options[k] for k in SCENARIO_OPTIONS if k in options})
        self._record = (record_seconds, record_seed)
        super().__init__(fresh_process=fresh_process, backend=backend, region_data=True, **options)
        self._region_rows = {x: k for k, x in enumerate(self.network.ids)}
        self._aip_rng = np.random.default_rng()

    def _prepare(self, scenario) -> None:
        predictors, given = self._aips
        self.predictors = resolve_predictors(predictors, list(self.regions), given)
        self._tables = entry_tables(scenario, list(self.regions), *self._record)

    def _core_config(self) -> dict:
        if self.local == "arrays":
            config = SumoNetEnv._core_config(self)  # the network's own ids: nothing is cut
            config.pop("regions", None)
            return {**config, "tables": [self._tables[x] for x in self.network.ids]}
        config = super()._core_config()
        ids = self.network.ids
        layouts = [region_layout(self.scenario.net_file, x).prefixed(region_prefix(x)) for x in ids]
        config.update(layouts=[asdict(x) for x in layouts], tables=[self._tables[x] for x in ids],
                      row_keys=[(x, 0) for x in ids], prefixes=[region_prefix(x) for x in ids])
        return config

    def set_predictors(self, predictors) -> None:
        """New AIPs (as ``predictors`` in the constructor), from the next decision on (DIALS's
        refresh); their memory starts empty."""
        self.predictors = resolve_predictors(predictors, list(self.regions), self._aips[1])
        for p in self.predictors.values():
            p.reset(1)

    def reset(self, seed=None, options=None):
        obs, infos = super().reset(seed=seed, options=options)
        # the AIPs' own stream, from the episode's SUMO seed
        self._aip_rng = np.random.default_rng(np.random.SeedSequence(int(self._last_seed), spawn_key=(1,)))
        for p in self.predictors.values():
            p.reset(1)
        return obs, infos

    def _core_step(self, actions: list[int]) -> tuple:
        dsets = self._region[1]
        rng = self._aip_rng
        influences = [self.predictors[x].sample(dsets[k][None], rng)[0].tolist()
                      for k, x in enumerate(self.network.ids)]
        return actions, influences


__all__ = ["IALSNetEnv", "resolve_predictors"]
