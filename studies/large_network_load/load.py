"""How long a network as large as users bring takes to load, and its load budget.

Makes an N x N grid of lights with SUMO's ``netgenerate`` (cached in ``--folder``, never
committed), then times ``sumo_net_v0``'s constructor and its first ``reset()`` (SUMO loading the
network in a worker, which sends no heartbeat meanwhile: ``ials_zoo.sumo.command.load_budget``).

    python studies/large_network_load/load.py --size 120      # 128 MiB, 14,400 lights
"""

from __future__ import annotations

import argparse
import os
import subprocess
import time
from pathlib import Path

import sumo

from ials_zoo import sumo_net_v0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=120, help="lights per side (default 120)")
    parser.add_argument("--folder", default="/tmp/ials_zoo_large_network", help="where the network is kept")
    args = parser.parse_args()
    if args.size < 2:
        parser.error(f"--size must be >= 2, got {args.size}")
    folder = Path(args.folder)
    folder.mkdir(parents=True, exist_ok=True)
    net, routes = folder / f"grid{args.size}.net.xml", folder / "empty.rou.xml"
    if not net.is_file():
        start = time.perf_counter()
        subprocess.run([os.path.join(sumo.SUMO_HOME, "bin", "netgenerate"), "--grid", "--grid.number", str(args.size),
                        "--default-junction-type", "traffic_light", "--no-turnarounds", "true", "-o", str(net)],
                       check=True, capture_output=True)
        print(f"netgenerate: {time.perf_counter() - start:.1f} s", flush=True)
    routes.write_text("<routes/>")
    print(f"network: {net.stat().st_size / 2**20:.0f} MiB", flush=True)
    start = time.perf_counter()
    env = sumo_net_v0.parallel_env(net_file=str(net), route_files=[str(routes)], max_cycles=1)
    print(f"constructed: {time.perf_counter() - start:.1f} s; {len(env.possible_agents):,} lights", flush=True)
    try:
        start = time.perf_counter()
        env.reset(seed=0)
        print(f"reset (SUMO loads it): {time.perf_counter() - start:.1f} s; load budget {env._sim.load_seconds:.0f} s")
    finally:
        env.close()


if __name__ == "__main__":
    main()
