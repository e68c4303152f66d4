"""Diagnostic: how often is an outgoing lane of a light full back to its start (spill-back) in the GS?"""

import sys

import numpy as np

from ials_zoo.core.domains import get_domain
from ials_zoo.traffic.network import outgoing_edges

policy = sys.argv[1] if len(sys.argv) > 1 else "random"
dom = get_domain("traffic_grid_v0")
agents = dom.agents()
env = dom.parallel_env(learners=agents)
rng = np.random.default_rng(0)
from ials_zoo.evaluation import FrameStack, load_model

pol = None if policy in ("random", "constant") else load_model(policy)
watch = {"tls_0": 0, "tls_1": 1, "tls_12": 12}
blocked = {a: [] for a in watch}
for ep in range(3):
    obs, _ = env.reset(seed=ep)
    if pol is not None:
        pol.reset(ep)
        fs = FrameStack(getattr(pol, "frame_stack", 1))
        x = fs.reset(np.stack([obs[a] for a in agents]))
    while env.agents:
        if pol is None:
            acts = {a: int(rng.integers(2)) if policy == "random" else 0 for a in agents}
        else:
            acts = {a: int(u) for a, u in zip(agents, pol.act_all(x))}
        obs, *_ = env.step(acts)
        if env.agents and pol is not None:
            x = fs.step(np.stack([obs[a] for a in agents]))
        for a, i in watch.items():
            n = 0
            for e in outgoing_edges((5, 5), i):
                lane = e + "_0"
                try:
                    ids = env.sumo_query("lane", "getLastStepVehicleIDs", lane)
                except Exception:
                    continue
                if any(
                    env.sumo_query("vehicle", "getLanePosition", v) < 15
                    and env.sumo_query("vehicle", "getSpeed", v) < 2
                    for v in ids
                ):
                    n += 1
            blocked[a].append(n)
for a in watch:
    b = np.array(blocked[a])
    print(
        a,
        policy,
        "steps with >=1 outgoing lane blocked at its start:",
        f"{(b > 0).mean():.3f}",
        "mean blocked lanes",
        f"{b.mean():.3f}",
    )
env.close()
