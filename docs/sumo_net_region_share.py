"""Where a RESCO map's vehicles spend their time, against the lights' regions: the share of the
GS's vehicle-steps on the regions' edges (counted per region, and with a road in two regions
counted once), within 250 m of a stop line, and on the lights' outgoing edges (and the roads past
short exits). Every light on its own program, SUMO seed 0, counted every 10 s over the hour.

A local simulator of every region costs at least what SUMO charges for the vehicles it holds,
so this is the floor of the multi-agent IALS's cost (``docs/sumo_net.md``).

Usage: python docs/sumo_net_region_share.py [--net ingolstadt21]
"""

from __future__ import annotations

import argparse

from ials_zoo.sumo.command import close_any_simulation
from ials_zoo.sumo.lease import import_libsumo
from ials_zoo.sumo_net.core import episode_command
from ials_zoo.sumo_net.env import scenario_of
from ials_zoo.sumo_net.network import read_network
from ials_zoo.sumo_net.regions import regions_of

NEAR_METRES = 250.0


class _Holder:
    """What :func:`close_any_simulation` closes: libsumo and its running flag."""

    def __init__(self, ls):
        self.ls, self.running = ls, False


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--net", default="ingolstadt21")
    args = parser.parse_args(argv)
    scenario = scenario_of(net=args.net)
    regions = regions_of(scenario.net_file)
    lights = read_network(scenario.net_file).lights
    per_region = [e for r in regions.values() for e in r.edges]
    outgoing = [e for r in regions.values() for e in r.outgoing + r.beyond]
    ls = import_libsumo()
    holder, raw = _Holder(ls), ls._libsumo
    ls.start(episode_command(scenario.net_file, scenario.route_files, scenario.begin, scenario.end, 0))
    holder.running = True
    counts = dict.fromkeys(("all", "regions", "union", "near", "outgoing"), 0)
    try:
        for t in range(scenario.end - scenario.begin):
            raw.simulation_step(0.0)
            if t % 10:
                continue
            on = {e: raw.edge_getLastStepVehicleNumber(e) for e in set(per_region)}
            counts["all"] += raw.vehicle_getIDCount()
            counts["regions"] += sum(on[e] for e in per_region)
            counts["union"] += sum(on.values())
            counts["outgoing"] += sum(raw.edge_getLastStepVehicleNumber(e) for e in outgoing)
            for x in lights:
                for lane, length in zip(x.lanes, x.lane_lengths):
                    counts["near"] += sum(1 for v in raw.lane_getLastStepVehicleIDs(lane)
                                          if length - raw.vehicle_getLanePosition(v) <= NEAR_METRES)
    finally:
        close_any_simulation(holder)
    share = {k: v / counts["all"] for k, v in counts.items() if k != "all"}
    print(f"{args.net}: vehicle-steps on the regions {share['regions']:.3f} (a road once: {share['union']:.3f}); "
          f"within {NEAR_METRES:.0f} m of a stop line {share['near']:.3f}; on the outgoing edges {share['outgoing']:.3f}")


if __name__ == "__main__":
    main()
