"""Why the GS's default mode (a worker forked per episode) trails the in-process mode on small maps.

Usage: python docs/sumo_net_worker_overhead.py [--net cologne8] [--repeats 5] [--out F.json]

Run it on a quiet machine: it measures, in one run,
1. the GS's share of raw SUMO in both modes (as ``ials-zoo bench``), and SUMO's own steps per second
   in each (raw SUMO time only);
2. a worker round trip (``ials_zoo.processes.Worker`` answering a trivial call), median and 10th/90th
   percentiles over 3,000 calls;
3. the minor page faults of one episode's steps, in this process and in a fresh worker;
4. the default mode again beside two busy loops at the lowest priority (nice 19), which keep the
   cores from idling: if idle cores waking up were the cost, the share would rise.
Figures in docs/sumo_net.md ("Speed").
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time

import numpy as np

from ials_zoo.processes import Worker
from ials_zoo.sumo_net.benchmark import MODES, bench_map
from ials_zoo.sumo_net.env import SumoNetEnv


def round_trip_us(calls: int = 3000) -> list[float]:
    worker = Worker(dict, (), name="round trip")
    try:
        lat = []
        for _ in range(calls):
            t = time.perf_counter()
            worker.call("get", "x")
            lat.append(time.perf_counter() - t)
    finally:
        worker.close()
    return [statistics.median(lat) * 1e6, float(np.percentile(lat, 10)) * 1e6, float(np.percentile(lat, 90)) * 1e6]


def _minor_faults(pid: int | None) -> int:
    if pid is None:
        return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    with open(f"/proc/{pid}/stat") as f:
        return int(f.read().rsplit(")", 1)[1].split()[7])


def episode_faults(net: str, mode: str, seed: int = 0) -> int:
    """Minor page faults during one episode's steps (after a warm-up episode in the same env)."""
    env = SumoNetEnv(net=net, **MODES[mode])
    try:
        env.reset(seed=seed + 1)
        env.reset(seed=seed)
        pid = env._sim.worker_pid
        before = _minor_faults(pid)
        while env.agents:
            env.step({a: 0 for a in env.agents})
        return _minor_faults(pid) - before
    finally:
        env.close()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--net", default="cologne8")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    out = {"net": args.net}
    for mode in MODES:
        r = bench_map(args.net, repeats=args.repeats, mode=mode)
        out[mode] = r
        print(f"{mode}: GS / raw SUMO {r['gs_share_of_raw']}, SUMO steps/s {r['raw_sumo_steps_per_s']}", flush=True)
    out["round_trip_us"] = round_trip_us()
    print(f"worker round trip, µs: median, p10, p90 = {out['round_trip_us']}", flush=True)
    out["faults"] = {mode: episode_faults(args.net, mode) for mode in MODES}
    print(f"minor page faults of one episode's steps: {out['faults']}", flush=True)
    spinners = [subprocess.Popen(["nice", "-n", "19", sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        mode = next(iter(MODES))
        r = bench_map(args.net, repeats=args.repeats, mode=mode)
        out["default beside two nice-19 busy loops"] = r
        print(f"{mode} beside two nice-19 busy loops: GS / raw SUMO {r['gs_share_of_raw']}", flush=True)
    finally:
        for p in spinners:
            p.kill()
    if args.out:
        with open(args.out, "w") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
