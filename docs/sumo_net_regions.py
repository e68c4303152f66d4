"""Every light's region of a RESCO map, replayed: what a local simulator of every region would
cost against the GS, and how closely it reproduces each light's lanes when fed the GS's own
influence sources.

1. The GS: the map's hour in libsumo, every light on its own program; each step, the vehicles
   that appear on a region's edges (from outside it, or inserted there) are recorded with their
   lane, position, speed, type and the rest of their route inside the region, and each light's
   controlled lanes are read (vehicles, halting vehicles).
2. The local simulators: every region cut from the network (``ials_zoo.sumo_net.regions``, ids
   prefixed by the light) side by side in one SUMO simulation, the lights on the same programs
   from the same second; each step the recorded vehicles are inserted where and as the GS had
   them, and the same lanes are read.
3. Cost: seconds per step of each simulation alone (the GS run again without the recording; the
   local simulators with their insertions), their ratio is the cost per agent-step of the local
   simulators against the GS (both simulate every light). Fidelity: per controlled lane and
   step, the mean absolute difference of vehicles and of halting vehicles, against the GS's mean.

``--cap`` sets the incoming chains' length cap; ``--downstream M`` extends every outgoing edge
by the road beyond it (through nodes that only join a road's pieces) up to M metres, to see how
much of the replay's error is the missing downstream.

Usage: python docs/sumo_net_regions.py [--net ingolstadt21] [--seconds 3600] [--cap 400] [--downstream 0]
       [--same-speed-factor] [--depart-speed gs|max] [--exit-lane] [--noise-floor]
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ials_zoo.sumo.command import sumo_command
from ials_zoo.sumo_net.network import read_network
from ials_zoo.sumo_net.regions import CHAIN_CAP_METRES, cut_network, netconvert, regions_of
from ials_zoo.sumo_net.scenario import make_scenario


def _vtypes(route_files, out: Path) -> Path:
    """The route files' vehicle types as an additional file (the cut networks carry none)."""
    root = ET.Element("additional")
    for f in route_files:
        for vt in ET.parse(f).getroot().iter("vType"):
            root.append(vt)
    ET.ElementTree(root).write(out)
    return out


def _start(ls, cmd, begin, end):
    ls.start(cmd + ["--begin", str(begin), "--end", str(end), "--time-to-teleport", "-1"])


def _lanes_state(ls, lanes):
    return np.array([(ls.lane.getLastStepVehicleNumber(x), ls.lane.getLastStepHaltingNumber(x)) for x in lanes], float)


def run_gs(ls, sc, regions, lanes, seconds, record: bool):
    """The GS's hour: ``(seconds per step, entries per step, lane states per step)``."""
    _start(ls, sumo_command(0, net=sc.net_file, routes=sc.route_files), sc.begin, sc.begin + seconds)
    region_edges = {light: set(r.edges) for light, r in regions.items()}
    present = {light: set() for light in regions}
    leaving = {light: {} for light in regions}  # vehicle -> its entry (its exit lane is filled in as it goes)
    entries, states, spent = [], [], 0.0
    for _ in range(seconds):
        t0 = time.perf_counter()
        ls.simulationStep()
        spent += time.perf_counter() - t0
        if not record:
            continue
        step = []
        alive = set(ls.vehicle.getIDList())
        for light, edges in region_edges.items():
            now = {v for e in edges for v in ls.edge.getLastStepVehicleIDs(e)}
            # a vehicle inside the region stays known while it crosses a junction's internal lanes
            # (it is then on no region edge): it entered once, and is inserted once
            known = {v for v in present[light] if v in alive
                     and (v in now or ls.vehicle.getRoadID(v).startswith(":"))}
            for v in sorted(now - known):
                route, index = ls.vehicle.getRoute(v), ls.vehicle.getRouteIndex(v)
                inside = []
                for e in route[max(index, 0):]:
                    if e not in edges:
                        break
                    inside.append(e)
                if inside:
                    step.append([light, v, tuple(inside), ls.vehicle.getLaneIndex(v), ls.vehicle.getLanePosition(v),
                                 ls.vehicle.getSpeed(v), ls.vehicle.getTypeID(v), ls.vehicle.getSpeedFactor(v), None])
                    leaving[light][v] = step[-1]
            for v in now:  # the lane a vehicle leaves the region by: the last one it holds on its last edge
                entry = leaving[light].get(v)
                if entry is not None and ls.vehicle.getRoadID(v) == entry[2][-1]:
                    entry[-1] = ls.vehicle.getLaneIndex(v)
            leaving[light] = {v: e for v, e in leaving[light].items() if v in known or v in now}
            present[light] = known | now
        entries.append(step)
        states.append(_lanes_state(ls, lanes))
    ls.close()
    return spent / seconds, entries, states


def run_local(ls, sc, merged, vtypes, lanes, entries, seconds, same_speed_factor=False, depart_speed="gs", seed=0,
              exit_lane=False):
    """The local simulators fed the GS's entries: ``(seconds per step, lane states per step, mean
    vehicles waiting to be inserted)``; ``same_speed_factor``: each keeps the GS's speed factor
    (otherwise it draws its own from its type, as a new vehicle does); ``depart_speed``: ``"gs"``
    inserts at the GS's speed (SUMO delays an insertion until that speed is safe), ``"max"`` at
    the highest safe speed; ``exit_lane``: each aims for the lane by which it left the region in
    the GS (its route there goes on beyond the region, which its lane choices inside follow)."""
    _start(ls, sumo_command(seed, net=merged, additionals=[vtypes]), sc.begin, sc.begin + seconds)
    states, spent, n, pending = [], 0.0, 0, 0
    for step in entries:
        t0 = time.perf_counter()
        for light, v, edges, lane, pos, speed, vtype, factor, out_lane in step:
            rid = f"r{n}"
            n += 1
            ls.route.add(rid, [f"{light}__{e}" for e in edges])
            vid = f"{light}__{v}__{n}"
            ls.vehicle.add(vid, rid, typeID=vtype, depart="now", departLane=str(lane),
                           departPos=str(max(pos, 0.0)), departSpeed=str(speed) if depart_speed == "gs" else "max",
                           arrivalLane=str(out_lane) if exit_lane and out_lane is not None else "current")
            if same_speed_factor:
                ls.vehicle.setSpeedFactor(vid, factor)
        ls.simulationStep()
        spent += time.perf_counter() - t0
        pending += len(ls.simulation.getPendingVehicles())
        states.append(_lanes_state(ls, lanes))
    ls.close()
    return spent / seconds, states, pending / max(len(entries), 1)


def _downstream(net_file: str, regions: dict, metres: float) -> dict:
    """Every region with its outgoing roads followed downstream up to ``metres``."""
    import sumolib

    net = sumolib.net.readNet(net_file, withInternal=False)
    lights = {t.getID() for t in net.getTrafficLights()}
    out = {}
    for light, r in regions.items():
        extra = []
        for e in r.outgoing:
            edge, covered = net.getEdge(e), 0.0
            while covered < metres:
                node = edge.getToNode()
                ahead = [x for x in node.getOutgoing() if x.getToNode() is not edge.getFromNode()]
                if node.getID() in lights or len(ahead) != 1 or ahead[0].getID() in r.edges or ahead[0].getID() in extra:
                    break
                edge = ahead[0]
                extra.append(edge.getID())
                covered += edge.getLength()
        out[light] = dataclasses.replace(r, outgoing=r.outgoing + tuple(extra))
    return out


def _past_short_exits(net_file: str, regions: dict, metres: float) -> dict:
    """Every region with the roads after each outgoing edge shorter than ``metres`` (one hop):
    where two junctions are that close, the second one's queue reaches back into the first."""
    import sumolib

    net = sumolib.net.readNet(net_file, withInternal=False)
    out = {}
    for light, r in regions.items():
        extra = [x.getID() for e in r.outgoing if net.getEdge(e).getLength() < metres
                 for x in net.getEdge(e).getOutgoing() if x.getID() not in r.edges]
        out[light] = dataclasses.replace(r, outgoing=r.outgoing + tuple(dict.fromkeys(extra)))
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--net", default="ingolstadt21")
    parser.add_argument("--seconds", type=int, default=3600)
    parser.add_argument("--cap", type=float, default=CHAIN_CAP_METRES)
    parser.add_argument("--downstream", type=float, default=0.0)
    parser.add_argument("--same-speed-factor", action="store_true",
                        help="inserted vehicles keep the GS's speed factor")
    parser.add_argument("--exit-lane", action="store_true",
                        help="inserted vehicles aim for the lane by which they left the region in the GS")
    parser.add_argument("--past-short", type=float, default=0.0, metavar="M",
                        help="also keep the roads after outgoing edges shorter than M metres")
    parser.add_argument("--worst", type=int, default=0, help="list the N lanes replayed worst")
    parser.add_argument("--noise-floor", action="store_true",
                        help="also replay with SUMO seed 1: how far two replays of the same entries differ")
    parser.add_argument("--depart-speed", choices=("gs", "max"), default="gs",
                        help="insert at the GS's speed (default) or at the highest safe speed")
    args = parser.parse_args(argv)
    import libsumo as ls

    sc = make_scenario(net=args.net)
    network = read_network(sc.net_file)
    regions = regions_of(sc.net_file, cap=args.cap)
    if args.downstream > 0:
        regions = _downstream(sc.net_file, regions, args.downstream)
    if args.past_short > 0:
        regions = _past_short_exits(sc.net_file, regions, args.past_short)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cuts = [str(cut_network(sc.net_file, r, tmp / f"{i}.net.xml", prefix=f"{light}__"))
                for i, (light, r) in enumerate(regions.items())]
        merged = tmp / "regions.net.xml"
        netconvert(["--sumo-net-file", ",".join(cuts), "--output-file", str(merged)], "merging the regions", 600)
        vtypes = _vtypes(sc.route_files, tmp / "vtypes.add.xml")
        gs_lanes = [x for light in network.lights for x in dict.fromkeys(light.lanes)]
        ls_lanes = [f"{light.id}__{x}" for light in network.lights for x in dict.fromkeys(light.lanes)]
        gs_step, _, _ = run_gs(ls, sc, regions, gs_lanes, args.seconds, record=False)
        _, entries, gs_states = run_gs(ls, sc, regions, gs_lanes, args.seconds, record=True)
        ls_step, ls_states, pending = run_local(ls, sc, str(merged), vtypes, ls_lanes, entries, args.seconds,
                                                args.same_speed_factor, args.depart_speed, exit_lane=args.exit_lane)
        if args.noise_floor:
            _, again, _ = run_local(ls, sc, str(merged), vtypes, ls_lanes, entries, args.seconds,
                                    args.same_speed_factor, args.depart_speed, seed=1, exit_lane=args.exit_lane)
    gs_s, ls_s = np.array(gs_states), np.array(ls_states)
    error = np.abs(gs_s - ls_s).mean(axis=(0, 1))
    scale = np.maximum(gs_s.mean(axis=(0, 1)), 1e-9)
    inserted = sum(len(s) for s in entries)
    print(f"{args.net}, {args.seconds} s, cap {args.cap:g} m, downstream {args.downstream:g} m, {len(regions)} lights, "
          f"{sum(len(r.edges) for r in regions.values())} region edges, {len(gs_lanes)} controlled lanes, "
          f"{inserted:,} vehicles inserted into the regions, {pending:.1f} waiting to be inserted (mean over steps)"
          + (", the GS's speed factors" if args.same_speed_factor else "") + f", depart speed {args.depart_speed}"
          + (", exit lanes the GS's" if args.exit_lane else ""))
    print("| | GS | local simulators (every region) |")
    print("|---|---|---|")
    print(f"| µs per step | {gs_step * 1e6:,.0f} | {ls_step * 1e6:,.0f} (**{ls_step / gs_step:.2f}** of the GS) |")
    print(f"| vehicles per controlled lane (mean) | {scale[0]:.3f} | mean abs. difference {error[0]:.3f} "
          f"({error[0] / scale[0]:.1%} of the GS's mean) |")
    print(f"| halting vehicles per controlled lane (mean) | {scale[1]:.3f} | mean abs. difference {error[1]:.3f} "
          f"({error[1] / scale[1]:.1%}) |")
    bias = (ls_s - gs_s).mean(axis=(0, 1))
    print(f"| mean signed difference (local - GS) | | vehicles {bias[0]:+.3f}, halting {bias[1]:+.3f} |")
    if args.worst:
        per_lane = np.abs(gs_s - ls_s).mean(axis=0)[:, 0]
        for k in np.argsort(per_lane)[::-1][:args.worst]:
            print(f"  {gs_lanes[k]}: vehicles GS {gs_s[:, k, 0].mean():.2f}, local {ls_s[:, k, 0].mean():.2f}, "
                  f"mean abs. difference {per_lane[k]:.2f}")
    if args.noise_floor:  # SUMO's own randomness (driver imperfection) with the same entries
        floor = np.abs(ls_s - np.array(again)).mean(axis=(0, 1))
        print(f"| two replays, SUMO seeds 0 and 1 | | vehicles {floor[0]:.3f} ({floor[0] / scale[0]:.1%}), "
              f"halting {floor[1]:.3f} ({floor[1] / scale[1]:.1%}) |")


if __name__ == "__main__":
    main()
