"""Per lane of tls_0 / tls_1: entries per episode, occupancy-count distribution, and entry rate
given the number of occupied cells of that lane (GS vs IALS with on-policy AIPs)."""

import sys

import numpy as np
import torch

torch.set_num_threads(1)
from ials_zoo.core.domains import get_domain
from ials_zoo.evaluation import FrameStack, load_model
from ials_zoo.influence import fidelity as F
from ials_zoo.influence.multi import make_ials_parallel_env

pol = sys.argv[1]
seed = int(sys.argv[2])
episodes = int(sys.argv[3])
dom = get_domain("traffic_grid_v0")
agents = dom.agents()
policy = pol if pol in ("random", "constant") else load_model(pol)
watch = [0, 1]


def record(env, ials=False):
    rng = np.random.default_rng(seed)
    cnt = np.zeros((2, 4, 10))
    ent = np.zeros((2, 4, 10))
    entered = np.zeros((2, 4))
    ret = np.zeros(2)
    for ep in range(episodes):
        obs, _ = env.reset(seed=seed * 1000 + ep)
        x = None
        if not isinstance(policy, str):
            policy.reset(ep)
            fs = FrameStack(getattr(policy, "frame_stack", 1))
            x = fs.reset(np.stack([obs[a] for a in agents]))
        while env.agents:
            before = {i: obs[agents[i]][:36].reshape(4, 9).sum(1).astype(int) for i in watch}
            acts = F._joint_actions(policy, agents, 2, rng, obs, x)
            obs, r, _, _, infos = env.step({a: int(u) for a, u in zip(agents, acts)})
            for k, i in enumerate(watch):
                a = agents[i]
                u = infos[a]["influence"]
                for lane in range(4):
                    c = before[i][lane]
                    cnt[k, lane, c] += 1
                    ent[k, lane, c] += u[lane]
                ret[k] += r[a]
                if ials:
                    entered[k] += env.core.ls.last_entries[i]
            if env.agents and x is not None:
                x = fs.step(np.stack([obs[a] for a in agents]))
    return cnt, ent, entered / episodes, ret / episodes


gs_env = dom.parallel_env(learners=agents)
g = record(gs_env)
gs_env.close()
aips = F.on_policy_aips("traffic_grid_v0", agents, policy, 10000, seed + 100_000, True, {}, influence_lags=1, clock_horizon=0)
ie = make_ials_parallel_env("traffic_grid_v0", agents, predictor=aips, seed=seed)
s = record(ie, True)
ie.close()
np.set_printoptions(precision=3, suppress=True, linewidth=220)
for k, i in enumerate(watch):
    print(f"tls_{i} return GS {g[3][k]:.1f} IALS {s[3][k]:.1f}; IALS cars inserted per episode {s[2][k]}")
    for lane, name in enumerate("NESW"):
        ge, se = g[1][k, lane].sum() / episodes, s[1][k, lane].sum() / episodes
        print(f"  {name}: entries/ep GS {ge:.1f} IALS {se:.1f}")
        print("     P(count) GS  ", g[0][k, lane] / g[0][k, lane].sum())
        print("     P(count) IALS", s[0][k, lane] / s[0][k, lane].sum())
        print("     rate|c GS    ", g[1][k, lane] / np.maximum(g[0][k, lane], 1))
        print("     rate|c IALS  ", s[1][k, lane] / np.maximum(s[0][k, lane], 1))
