"""Where a RESCO map's vehicles spend their time, against the lights' regions: the share of the
GS's vehicle-steps in the regions (counted per region, and with a road in two regions counted
once), within 250 m of a stop line, and on the lights' outgoing edges (and the roads past short
exits). Every light on its own program, SUMO seed 0, counted every 10 s over the hour.

A region is counted as its local simulator holds it (:mod:`ials_zoo.sumo_net.regions`): on an
entry edge only past its entry offset, on an outgoing edge only up to where vehicles leave
(an estimate: a vehicle going on to the roads past a short exit stays longer). By part: the
lights' incoming edges (what their observations read, from 200 m before the stop line), the
chains' edges upstream of them, the outgoing edges and the roads past short exits.

A local simulator of every region costs at least what SUMO charges for the vehicles it holds,
so this is the floor of the multi-agent IALS's cost (``docs/sumo_net.md``).

Usage: python studies/ials_real_maps/region_share.py [--net ingolstadt21]
"""

from __future__ import annotations

import argparse

from ials_zoo.sumo.command import close_any_simulation
from ials_zoo.sumo.lease import import_libsumo
from ials_zoo.sumo_net.core import episode_command
from ials_zoo.sumo_net.network import read_network
from ials_zoo.sumo_net.regions import regions_of
from ials_zoo.sumo_net.scenario import scenario_of

NEAR_METRES = 250.0


class _Holder:
    """What :func:`close_any_simulation` closes: libsumo and its running flag."""

    def __init__(self, ls):
        self.ls, self.running = ls, False


PARTS = ("incoming", "upstream", "outgoing", "beyond")


def _spans(regions) -> list[dict]:
    """Per region, per edge: ``(from, to, part)``, the stretch of lane positions it holds and
    which part of the region the edge is (:data:`PARTS`)."""
    out = []
    for r in regions.values():
        offset, leave = dict(zip(r.sources, r.entry_offsets)), dict(r.exits)
        part = {e: "upstream" for c in r.chains for e in c[:-1]}
        part.update({e: "beyond" for e in r.beyond})
        part.update({e: "outgoing" for e in r.outgoing})
        part.update({c[-1]: "incoming" for c in r.chains})
        out.append({e: (offset.get(e, 0.0), leave.get(e, float("inf")), part[e]) for e in r.edges})
    return out


def _held(raw, span: dict) -> dict:
    """The vehicles a region's local simulator would hold now, by vehicle: its part."""
    held = {}
    for e, (lo, hi, part) in span.items():
        for v in raw.edge_getLastStepVehicleIDs(e):
            if (lo == 0 and hi == float("inf")) or lo <= raw.vehicle_getLanePosition(v) <= hi:
                held[v] = part
    return held


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--net", default="ingolstadt21")
    args = parser.parse_args(argv)
    scenario = scenario_of(net=args.net)
    regions = regions_of(scenario.net_file)
    lights = read_network(scenario.net_file).lights
    outgoing = [e for r in regions.values() for e in r.outgoing + r.beyond]
    spans = _spans(regions)
    ls = import_libsumo()
    holder, raw = _Holder(ls), ls._libsumo
    ls.start(episode_command(scenario.net_file, scenario.route_files, scenario.begin, scenario.end, 0))
    holder.running = True
    counts = dict.fromkeys(("all", "regions", "union", "near", "whole_outgoing", *PARTS), 0)
    try:
        for t in range(scenario.end - scenario.begin):
            raw.simulation_step(0.0)
            if t % 10:
                continue
            held = [_held(raw, span) for span in spans]
            counts["all"] += raw.vehicle_getIDCount()
            counts["regions"] += sum(map(len, held))
            counts["union"] += len(set().union(*held))
            for h in held:
                for part in h.values():
                    counts[part] += 1
            counts["whole_outgoing"] += sum(raw.edge_getLastStepVehicleNumber(e) for e in outgoing)
            for x in lights:
                for lane, length in zip(x.lanes, x.lane_lengths):
                    counts["near"] += sum(1 for v in raw.lane_getLastStepVehicleIDs(lane)
                                          if length - raw.vehicle_getLanePosition(v) <= NEAR_METRES)
    finally:
        close_any_simulation(holder)
    share = {k: v / counts["all"] for k, v in counts.items() if k != "all"}
    print(f"{args.net}: vehicle-steps in the regions {share['regions']:.3f} (a road once: {share['union']:.3f}): "
          + ", ".join(f"{part} edges {share[part]:.3f}" for part in PARTS)
          + f"; within {NEAR_METRES:.0f} m of a stop line {share['near']:.3f}; on the whole outgoing edges "
          f"{share['whole_outgoing']:.3f}")


if __name__ == "__main__":
    main()
