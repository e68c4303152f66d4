"""Diagnostic: in the traffic multi-agent IALS, how many sampled cars are dropped (lane start blocked)?"""

import sys

import numpy as np
import torch

torch.set_num_threads(1)
from ials_zoo.evaluation import FrameStack, load_model
from ials_zoo.influence.multi import make_ials_parallel_env

pol = sys.argv[1] if len(sys.argv) > 1 else "random"
env = make_ials_parallel_env("traffic_grid_v0", seed=0)
agents = env.possible_agents
policy = None if pol in ("random", "constant") else load_model(pol)
rng = np.random.default_rng(0)
sampled = np.zeros((25, 4))
entered = np.zeros((25, 4))
for ep in range(3):
    obs, _ = env.reset(seed=ep)
    if policy is not None:
        policy.reset(ep)
        fs = FrameStack(getattr(policy, "frame_stack", 1))
        x = fs.reset(np.stack([obs[a] for a in agents]))
    while env.agents:
        if policy is None:
            acts = rng.integers(2, size=25) if pol == "random" else np.zeros(25, int)
        else:
            acts = policy.act_all(x)
        obs, r, _, _, infos = env.step({a: int(u) for a, u in zip(agents, acts)})
        sampled += np.stack([infos[a]["influence"] for a in agents])
        entered += env.core.ls.last_entries
        if env.agents and policy is not None:
            x = fs.step(np.stack([obs[a] for a in agents]))
for i in (0, 1, 12):
    print(pol[:20], f"tls_{i}", "sampled", sampled[i].astype(int), "entered", entered[i].astype(int))
print("all: dropped share", f"{1 - entered.sum() / sampled.sum():.3f}")
