"""The traffic LS with the GS's recorded influence, the IPPO lights acting on the LS's own
observations (closed loop): return vs the GS's, and vs the same LS replaying the GS's actions."""

import sys

import numpy as np
import torch

torch.set_num_threads(1)
from ials_zoo.core.domains import get_domain
from ials_zoo.evaluation import FrameStack, load_model

pol = sys.argv[1]
episodes = int(sys.argv[2])
dom = get_domain("traffic_grid_v0")
agents = dom.agents()
watch = ["tls_0", "tls_1", "tls_12"]
idx = [agents.index(a) for a in watch]
policy = load_model(pol)
gs = dom.parallel_env(learners=agents)
records = []
for ep in range(episodes):
    obs, _ = gs.reset(seed=ep)
    policy.reset(ep)
    fs = FrameStack(getattr(policy, "frame_stack", 1))
    x = fs.reset(np.stack([obs[a] for a in agents]))
    rec = {"u": [], "a": [], "r": np.zeros(3), "switch": np.zeros(3)}
    while gs.agents:
        acts = policy.act_all(x)
        obs, r, _, _, infos = gs.step({a: int(u) for a, u in zip(agents, acts)})
        rec["u"].append(np.stack([infos[a]["influence"] for a in watch]))
        rec["a"].append(acts[idx].copy())
        rec["r"] += [r[a] for a in watch]
        rec["switch"] += acts[idx]
        if gs.agents:
            x = fs.step(np.stack([obs[a] for a in agents]))
    records.append(rec)
gs.close()
ls = dom.local_simulator(watch, n_envs=1)
res = {"gs": [], "replay": [], "closed": [], "sw_gs": [], "sw_closed": []}
for ep, rec in enumerate(records):
    # replay: GS actions
    ls.reset(seed=ep)
    ret = np.zeros(3)
    for t in range(len(rec["u"])):
        _, r, _ = ls.step(np.asarray(rec["a"][t], np.int64), rec["u"][t].astype(np.int64))
        ret += r
    res["replay"].append(ret)
    # closed loop: the policy acts on the LS's observations
    obs, _ = ls.reset(seed=ep)
    policy.reset(ep)
    fs = FrameStack(getattr(policy, "frame_stack", 1))
    full = np.zeros((25, obs.shape[1]), np.float32)
    full[idx] = obs
    x = fs.reset(full)
    ret = np.zeros(3)
    sw = np.zeros(3)
    for t in range(len(rec["u"])):
        acts = policy.act_all(x)[idx]
        obs, r, _ = ls.step(np.asarray(acts, np.int64), rec["u"][t].astype(np.int64))
        ret += r
        sw += acts
        full = np.zeros((25, obs.shape[1]), np.float32)
        full[idx] = obs
        x = fs.step(full)
    res["closed"].append(ret)
    res["gs"].append(rec["r"])
    res["sw_gs"].append(rec["switch"])
    res["sw_closed"].append(sw)
for k in res:
    v = np.array(res[k])
    print(k, "mean", np.round(v.mean(0), 1), "sd", np.round(v.std(0), 1))
ls.close()
