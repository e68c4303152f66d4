"""The array local simulator's calibration from the GS: how vehicles share the lanes of an edge.

SUMO's drivers pick lanes for their whole route (its "best lanes" look past the region) and
change lanes to gain speed; a region's routes end at its exits, so the array model cannot know
why a driver keeps to one of two lanes that both lead on. On ingolstadt21 one approach's right
lane carried a tenth of its vehicles in the GS, and half in the first array model. So a GS run
measures it: each lane's mean vehicles, over its edge's, for every edge of more than one lane
in a region (:func:`lane_shares`). A vehicle then takes, among the lanes that lead on, the one
with the fewest vehicles for its share (:meth:`ials_zoo.sumo_net.arrays.ArraySim._choose_next`).

Measured over the hour on every light (``studies/arrays_local``), it brought the worst four
lights of ingolstadt21 closer (vehicles 46% -> 35% of the GS's mean at 600 s) but not the maps as
a whole (ingolstadt21 38.3% -> 37.1%, cologne8 13.0% -> 13.6%), so the IALS does not use it by
default; the replay takes it as ``calibration=``, the core as ``lane_shares=``.

Recorded once per network, hour and seed (the map's hour, every light on its own program, SUMO
seed 1: the replay contract is judged on seed 0), cached as JSON beside the entry tables
(``$IALS_ZOO_CACHE/sumo_net``, or ``~/.cache/ials_zoo/sumo_net``), read back with limits.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from ials_zoo.sumo.command import load_budget
from ials_zoo.sumo.lease import SimHandle
from ials_zoo.sumo_net.regions import EXIT_METRES, read_sumolib, regions_of
from ials_zoo.sumo_net.replay import ReplayCore
from ials_zoo.utils import parse_untrusted_json_object

CALIBRATION_SEED = 1
MAX_CALIBRATION_BYTES = 16 << 20
VERSION = 1


def _path(scenario, seconds: int, seed: int) -> Path:
    root = os.environ.get("IALS_ZOO_CACHE")
    key = json.dumps([VERSION, scenario.name, os.path.getsize(scenario.net_file), scenario.begin, seconds, seed,
                      EXIT_METRES])
    h = hashlib.sha256(key.encode()).hexdigest()[:12]
    return (Path(root) if root else Path.home() / ".cache" / "ials_zoo") / "sumo_net" / f"lanes_{h}.json"


def shared_lanes(net_file: str) -> list[str]:
    """Every lane of an edge of more than one lane in some light's region."""
    net = read_sumolib(net_file)
    edges = dict.fromkeys(e for r in regions_of(net_file).values() for e in r.edges)
    return [lane.getID() for e in edges for lane in net.getEdge(e).getLanes() if len(net.getEdge(e).getLanes()) > 1]


def lane_shares(scenario, seconds: int | None = None, seed: int = CALIBRATION_SEED) -> dict[str, float]:
    """Per lane of :func:`shared_lanes`: its mean vehicles over its edge's, in the GS's
    ``seconds`` (default: the map's hour) with every light on its own program (module docstring);
    cached. An edge the GS left empty shares its lanes equally."""
    seconds = int(seconds or scenario.end - scenario.begin)
    path = _path(scenario, seconds, seed)
    if path.is_file() and path.stat().st_size <= MAX_CALIBRATION_BYTES:
        data = parse_untrusted_json_object(path.read_bytes(), f"lane calibration {path}")
        shares = data.get("shares")
        if data.get("network") == scenario.name and isinstance(shares, dict) and all(
                isinstance(k, str) and isinstance(v, (int, float)) for k, v in shares.items()):
            return {k: float(v) for k, v in shares.items()}
    shares = _measure(scenario, seconds, seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text(json.dumps({"network": scenario.name, "seconds": seconds, "seed": seed, "version": VERSION,
                               "shares": shares}))
    os.replace(tmp, path)  # never half-written
    return shares


def _measure(scenario, seconds: int, seed: int) -> dict[str, float]:
    lanes = shared_lanes(scenario.net_file)
    if not lanes:
        return {}
    sim = SimHandle("ials_zoo.sumo_net.replay:ReplayCore", {}, "auto", timeout=3600.0, loads=ReplayCore.LOADS,
                    load_seconds=load_budget(scenario.net_file, *scenario.route_files))
    try:
        _, states, _ = sim.call("record", scenario.net_file, scenario.route_files, scenario.begin, seconds, {}, lanes,
                                [], seconds + 1, seed)
    finally:
        sim.close()
    mean = np.asarray(states, np.float64)[:, :, 0].mean(axis=0)
    edge = [x.rsplit("_", 1)[0] for x in lanes]
    totals: dict[str, float] = {}
    for e, m in zip(edge, mean):
        totals[e] = totals.get(e, 0.0) + float(m)
    count = {e: edge.count(e) for e in totals}
    return {x: (float(m) / totals[e] if totals[e] > 0 else 1.0 / count[e]) for x, e, m in zip(lanes, edge, mean)}


__all__ = ["CALIBRATION_SEED", "lane_shares", "shared_lanes"]
