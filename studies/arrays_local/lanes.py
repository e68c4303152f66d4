"""Where the arrays' replay error lies, lane by lane (issue 50): the replay contract of
``run.py replay`` on both local simulators, then the lanes that carry most of the arrays' error,
with the GS's, the SUMO regions' and the arrays' mean vehicles and halting vehicles.

Usage: python studies/arrays_local/lanes.py NET [--seconds 1800] [--top 12] [--calibrated]
       [--lane=LANE --window T0 T1]   (the lane's vehicles / halting per second; write --lane=ID,
       with "=", for ids that begin with "-")

Nothing is written: it prints (a replay of 1,800 s of ingolstadt21 takes about 30 s).
"""

from __future__ import annotations

import argparse
import tempfile

import numpy as np


def replays(net: str, seconds: int, calibrated: bool) -> dict:
    from ials_zoo.sumo_net.arrays_calibration import lane_shares
    from ials_zoo.sumo_net.regions import regions_of
    from ials_zoo.sumo_net.replay import replay_regions
    from ials_zoo.sumo_net.scenario import make_scenario

    scenario = make_scenario(net=net)
    regions = regions_of(scenario.net_file)
    out = {}
    for local in ("sumo", "arrays"):
        calibration = lane_shares(scenario) if calibrated and local == "arrays" else None
        with tempfile.TemporaryDirectory() as tmp:
            out[local] = replay_regions(scenario, regions, seconds, tmp, local=local, calibration=calibration)
        print(local, {k: round(v, 3) for k, v in out[local]["error"].items()}, flush=True)
    return out


def worst_lanes(out: dict, top: int) -> None:
    gs = np.asarray(out["arrays"]["gs"], float)  # [seconds, lanes, (vehicles, halting)]
    lanes, scale = out["arrays"]["lanes"], gs.mean(axis=(0, 1))
    local = {k: np.asarray(out[k]["local"], float) for k in ("sumo", "arrays")}
    share = {k: np.abs(gs - x).mean(axis=0) / scale for k, x in local.items()}  # each lane's part of the error
    print("lane | GS vehicles / halting | SUMO regions | arrays | part of the error: SUMO regions, arrays")
    for i in np.argsort(-share["arrays"][:, 0])[:top]:
        cells = [f"{x[:, i, 0].mean():.2f} / {x[:, i, 1].mean():.2f}" for x in (gs, local["sumo"], local["arrays"])]
        print(lanes[i], "|", " | ".join(cells), "|", f"{share['sumo'][i, 0]:.2f}, {share['arrays'][i, 0]:.2f}")


def series(out: dict, lane: str, start: int, end: int) -> None:
    i = out["arrays"]["lanes"].index(lane)
    gs, arrays = np.asarray(out["arrays"]["gs"], int), np.asarray(out["arrays"]["local"], int)
    sumo = np.asarray(out["sumo"]["local"], int)
    for t in range(start, end):
        print(t, "GS", gs[t, i], "SUMO regions", sumo[t, i], "arrays", arrays[t, i])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("net")
    parser.add_argument("--seconds", type=int, default=1800)
    parser.add_argument("--top", type=int, default=12)
    parser.add_argument("--calibrated", action="store_true", help="the arrays with their lane calibration")
    parser.add_argument("--lane", help="print this lane's states per second (--lane=ID)")
    parser.add_argument("--window", nargs=2, type=int, default=(0, 60), metavar=("T0", "T1"))
    args = parser.parse_args()
    if args.seconds < 1 or args.top < 1:
        parser.error("--seconds and --top must be positive")
    if not 0 <= args.window[0] < args.window[1] <= args.seconds:
        parser.error(f"--window: expected 0 <= T0 < T1 <= --seconds ({args.seconds})")
    out = replays(args.net, args.seconds, args.calibrated)
    worst_lanes(out, args.top)
    if args.lane:
        if args.lane not in out["arrays"]["lanes"]:
            parser.error(f"--lane: {args.lane!r} is not a lane of a light of {args.net}")
        series(out, args.lane, *args.window)


if __name__ == "__main__":
    main()
