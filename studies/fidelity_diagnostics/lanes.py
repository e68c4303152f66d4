"""Diagnostic: per incoming lane of a few lights, GS vs multi-agent IALS under one joint policy:
entries per episode and mean occupancy of the 9 cells (stop line first)."""

import sys

import numpy as np
import torch

torch.set_num_threads(1)
from ials_zoo.core.domains import get_domain
from ials_zoo.evaluation import FrameStack, load_model
from ials_zoo.influence import fidelity as F
from ials_zoo.influence.multi import make_ials_parallel_env

pol = sys.argv[1]
lr = float(sys.argv[2])
epochs = int(sys.argv[3])
episodes = int(sys.argv[4]) if len(sys.argv) > 4 else 6
dom = get_domain("traffic_grid_v0")
agents = dom.agents()
policy = pol if pol in ("random", "constant") else load_model(pol)
watch = [0, 1, 12]


def record(env):
    rng = np.random.default_rng(0)
    occ = np.zeros((3, 4, 9))
    ent = np.zeros((3, 4))
    ret = np.zeros(3)
    steps = 0
    for ep in range(episodes):
        obs, _ = env.reset(seed=ep)
        if not isinstance(policy, str):
            policy.reset(ep)
            fs = FrameStack(getattr(policy, "frame_stack", 1))
            x = fs.reset(np.stack([obs[a] for a in agents]))
        while env.agents:
            acts = F._joint_actions(policy, agents, 2, rng, obs, None if isinstance(policy, str) else x)
            obs, r, _, _, infos = env.step({a: int(u) for a, u in zip(agents, acts)})
            for k, i in enumerate(watch):
                a = agents[i]
                occ[k] += obs[a][:36].reshape(4, 9)
                ent[k] += infos[a]["influence"]
                ret[k] += r[a]
            steps += 1
            if env.agents and not isinstance(policy, str):
                x = fs.step(np.stack([obs[a] for a in agents]))
    return occ / steps, ent / episodes, ret / episodes


gs_env = dom.parallel_env(learners=agents)
g = record(gs_env)
gs_env.close()
aips = F.on_policy_aips("traffic_grid_v0", agents, policy, 10000, 100_000, True, {}, lr, epochs, influence_lags=1, clock_horizon=0)
ie = make_ials_parallel_env("traffic_grid_v0", agents, predictor=aips, seed=0)
s = record(ie)
ie.close()
np.set_printoptions(precision=2, suppress=True, linewidth=200)
for k, i in enumerate(watch):
    print(f"tls_{i} return GS {g[2][k]:.1f} IALS {s[2][k]:.1f}; entries/episode N,E,S,W GS {g[1][k]} IALS {s[1][k]}")
    for lane, name in enumerate("NESW"):
        print(f"   {name} occupancy GS  ", g[0][k][lane], "\n     occupancy IALS", s[0][k][lane])
