"""Every light's region of a RESCO map, replayed: what a local simulator of every region would
cost against the GS, and how closely it reproduces each light's lanes when fed the GS's own
influence sources (:mod:`ials_zoo.sumo_net.replay`: the GS records every vehicle that enters a
region; one SUMO simulation of every region side by side inserts them where the GS had them).

Cost: seconds per step of each simulation alone (the GS run again without the recording; the
local simulators with their insertions); their ratio is the cost per agent-step of the local
simulators against the GS (both simulate every light). Fidelity: per controlled lane and step,
the mean absolute difference of vehicles and of halting vehicles, against the GS's mean;
``--noise-floor`` adds the same figure between two replays of different SUMO seeds.

The variants measured on the way (inserting at the GS's speed, a new speed factor, the GS's exit
lanes, roads followed downstream) are in this script's history (commit 9170cfb).

Usage: python studies/ials_real_maps/regions.py [--net ingolstadt21] [--seconds 3600] [--cap 400]
       [--short-exit 50] [--reach 100] [--worst N] [--noise-floor] [--each]
"""

from __future__ import annotations

import argparse
import tempfile

import numpy as np

from ials_zoo.sumo_net.regions import CHAIN_CAP_METRES, REACH_METRES, SHORT_EXIT_METRES, regions_of
from ials_zoo.sumo_net.replay import replay_regions
from ials_zoo.sumo_net.scenario import make_scenario


def print_table(net: str, args, regions: dict, out: dict) -> None:
    e, gs = out["error"], np.asarray(out["gs"], float)
    cost = out["local_seconds_per_step"] / out["gs_seconds_per_step"]
    print(f"{net}, {args.seconds} s, cap {args.cap:g} m, short exits {args.short_exit:g} m, {len(regions)} lights, "
          f"{sum(len(r.edges) for r in regions.values())} region edges ({sum(r.length for r in regions.values()):,.0f} "
          f"lane-m, {sum(len(r.sources) for r in regions.values())} entry edges), {len(out['lanes'])} controlled lanes, "
          f"{out['inserted']:,} vehicles inserted into the regions")
    print("| | GS | local simulators (every region) |\n|---|---|---|")
    print(f"| µs per step | {out['gs_seconds_per_step'] * 1e6:,.0f} | {out['local_seconds_per_step'] * 1e6:,.0f} "
          f"(**{cost:.2f}** of the GS) |")
    for k, name in enumerate(("vehicles", "halting")):
        print(f"| {name} per controlled lane (mean) | {gs[:, :, k].mean():.3f} | mean abs. difference "
              f"{e[name]:.1%} of the GS's mean |")
    names = ("approach", "total_wait", "queue", "speed_sum", "reward")
    print("| the lights' RESCO observation per lane, and reward, every decision | | "
          + ", ".join(f"{k} {e[k]:.1%}" for k in names) + " |")
    if "noise_floor" in out:
        f = out["noise_floor"]
        print("| two replays, SUMO seeds 0 and 1 | | " + ", ".join(f"{k} {f[k]:.1%}" for k in ("vehicles", "halting", *names))
              + " |")


def print_worst(out: dict, n: int) -> None:
    gs, local = np.asarray(out["gs"], float), np.asarray(out["local"], float)
    per_lane = np.abs(gs - local).mean(axis=0)[:, 0]
    share = per_lane / max(per_lane.sum(), 1e-9)
    for k in np.argsort(per_lane)[::-1][:n]:
        print(f"  {out['lanes'][k]}: vehicles GS {gs[:, k, 0].mean():.2f}, local {local[:, k, 0].mean():.2f}, "
              f"mean abs. difference {per_lane[k]:.2f} ({share[k]:.0%} of the total)")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--net", default="ingolstadt21")
    parser.add_argument("--seconds", type=int, default=3600)
    parser.add_argument("--cap", type=float, default=CHAIN_CAP_METRES)
    parser.add_argument("--short-exit", type=float, default=SHORT_EXIT_METRES)
    parser.add_argument("--reach", type=float, default=REACH_METRES,
                        help="roads shorter than this from the stop line go on through junctions (m; 0: never)")
    parser.add_argument("--worst", type=int, default=0, help="list the N lanes replayed worst")
    parser.add_argument("--noise-floor", action="store_true")
    parser.add_argument("--each", action="store_true", help="also every region alone: a single learner's cost")
    args = parser.parse_args(argv)
    sc = make_scenario(net=args.net)
    regions = regions_of(sc.net_file, cap=args.cap, short_exit=args.short_exit, reach=args.reach)
    with tempfile.TemporaryDirectory() as tmp:
        out = replay_regions(sc, regions, args.seconds, tmp, measure_cost=True, noise_floor=args.noise_floor,
                             each=args.each)
    print_table(args.net, args, regions, out)
    print_worst(out, args.worst)
    if args.each:
        speedup = {k: out["gs_seconds_per_step"] / v for k, v in out["each_seconds_per_step"].items()}
        values = sorted(speedup.values())
        print(f"every region alone: the GS's seconds per step over the region's, median {np.median(values):.0f}x, "
              f"min {values[0]:.0f}x ({min(speedup, key=speedup.get)}), max {values[-1]:.0f}x")


if __name__ == "__main__":
    main()
