"""Diagnostic: the speed at which cars enter a light's incoming lanes in the GS (the LS inserts them at 10 m/s)."""

import sys

import numpy as np

from ials_zoo.core.domains import get_domain
from ials_zoo.traffic.network import incoming_edges

policy = sys.argv[1] if len(sys.argv) > 1 else "random"
dom = get_domain("traffic_grid_v0")
agents = dom.agents()
env = dom.parallel_env(learners=agents, scripted_learners=(policy == "scripted"))
rng = np.random.default_rng(0)
watch = {"tls_0": 0, "tls_1": 1, "tls_12": 12}
speeds = {(a, e): [] for a, i in watch.items() for e in incoming_edges((5, 5), i)}
prev = {k: set() for k in speeds}
for ep in range(3):
    env.reset(seed=ep)
    prev = {k: set() for k in speeds}
    while env.agents:
        env.step({a: int(rng.integers(2)) if policy == "random" else 0 for a in agents})
        for a, e in speeds:
            ids = set(env.sumo_query("lane", "getLastStepVehicleIDs", e + "_0"))
            for v in ids - prev[(a, e)]:
                speeds[(a, e)].append(env.sumo_query("vehicle", "getSpeed", v))
            prev[(a, e)] = ids
for (a, e), s in speeds.items():
    s = np.array(s)
    print(a, e, policy, f"entries {len(s)} mean entry speed {s.mean():.2f} m/s, share below 8 m/s {(s < 8).mean():.2f}")
env.close()
