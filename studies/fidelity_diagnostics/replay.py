"""Diagnostic: drive the traffic LS with the GS's own influence and actions (no AIP): does it give the GS's return?"""

import sys

import numpy as np
import torch

torch.set_num_threads(1)
from ials_zoo.core.domains import get_domain
from ials_zoo.evaluation import FrameStack, load_model

pol = sys.argv[1]
episodes = int(sys.argv[2]) if len(sys.argv) > 2 else 3
dom = get_domain("traffic_grid_v0")
agents = dom.agents()
watch = ["tls_0", "tls_1", "tls_12"]
policy = None if pol in ("random", "constant") else load_model(pol)
gs = dom.parallel_env(learners=agents)
rng = np.random.default_rng(0)
records = []
for ep in range(episodes):
    obs, _ = gs.reset(seed=ep)
    if policy is not None:
        policy.reset(ep)
        fs = FrameStack(getattr(policy, "frame_stack", 1))
        x = fs.reset(np.stack([obs[a] for a in agents]))
    rec = {a: {"u": [], "a": [], "r": 0.0, "occ": np.zeros(36)} for a in watch}
    while gs.agents:
        if policy is None:
            acts = rng.integers(2, size=25) if pol == "random" else np.zeros(25, int)
        else:
            acts = policy.act_all(x)
        act = {a: int(u) for a, u in zip(agents, acts)}
        obs, r, _, _, infos = gs.step(act)
        for a in watch:
            rec[a]["u"].append(np.asarray(infos[a]["influence"]))
            rec[a]["a"].append(act[a])
            rec[a]["r"] += r[a]
            rec[a]["occ"] += obs[a][:36]
        if gs.agents and policy is not None:
            x = fs.step(np.stack([obs[a] for a in agents]))
    records.append(rec)
gs.close()
ls = dom.local_simulator(watch, n_envs=1)
for ep, rec in enumerate(records):
    ls.reset(seed=ep)
    ret = np.zeros(3)
    occ = np.zeros((3, 36))
    entered = np.zeros((3, 4))
    sampled = np.zeros((3, 4))
    T = len(rec[watch[0]]["u"])
    for t in range(T):
        acts = np.array([rec[a]["a"][t] for a in watch], np.int64)
        u = np.stack([rec[a]["u"][t] for a in watch]).astype(np.int64)
        obs, r, _ = ls.step(acts, u)
        ret += r
        occ += obs[:, :36]
        entered += ls.last_entries
        sampled += u
    for k, a in enumerate(watch):
        print(
            f"ep {ep} {a}: return GS {rec[a]['r']:.1f} LS(replayed u, same actions) {ret[k]:.1f};"
            f" queue at stop line N,E,S,W GS {np.round(rec[a]['occ'].reshape(4, 9)[:, 0] / T, 2)} LS {np.round(occ[k].reshape(4, 9)[:, 0] / T, 2)};"
            f" cars given {sampled[k].astype(int)} entered {entered[k].astype(int)}"
        )
ls.close()
