"""Burstiness of arrivals per lane (tls_0, tls_1, tls_12): variance/mean of counts in 10-step windows,
and the share of arrivals within 3 steps of the previous one on the same lane; GS vs IALS.

    python studies/fidelity_diagnostics/bunching.py POLICY SEED EPISODES [STEPS LAGS]
"""

import sys

import numpy as np
import torch

torch.set_num_threads(1)
from ials_zoo.core.domains import get_domain
from ials_zoo.evaluation import load_model
from ials_zoo.influence import fidelity as F
from ials_zoo.influence.multi import make_ials_parallel_env

pol = sys.argv[1]
seed = int(sys.argv[2])
episodes = int(sys.argv[3])
# the AIPs' GS steps and lags: 10000 1 (the figures of the previous default) or 100000 3 (the default)
steps, lags = (int(sys.argv[4]), int(sys.argv[5])) if len(sys.argv) > 5 else (10_000, 1)
dom = get_domain("traffic_grid_v0")
agents = dom.agents()
policy = pol if pol in ("random", "constant") else load_model(pol)
watch = ["tls_0", "tls_1", "tls_12"]


def stats(env):
    tr = F.run(env, agents, watch, policy, episodes, seed, 2)
    out = {}
    for a in watch:
        disp, close = [], []
        for u in tr.influence[a]:  # [T, 4]
            T = u.shape[0] - u.shape[0] % 10
            w = u[:T].reshape(-1, 10, 4).sum(1)
            disp.append(w.var(0) / np.maximum(w.mean(0), 1e-9))
            for lane in range(4):
                t = np.flatnonzero(u[:, lane])
                if len(t) > 1:
                    close.append(np.mean(np.diff(t) <= 3))
        out[a] = (np.mean(disp, 0), np.mean(close))
    return out


gs_env = dom.parallel_env(learners=agents)
g = stats(gs_env)
gs_env.close()
aips = F.on_policy_aips("traffic_grid_v0", agents, policy, steps, seed + 100_000, True, {}, influence_lags=lags, clock_horizon=0)
ie = make_ials_parallel_env("traffic_grid_v0", agents, predictor=aips, seed=seed)
s = stats(ie)
ie.close()
for a in watch:
    print(
        a,
        "dispersion N,E,S,W GS",
        np.round(g[a][0], 2),
        "IALS",
        np.round(s[a][0], 2),
        "| share of gaps <= 3 steps GS",
        round(g[a][1], 3),
        "IALS",
        round(s[a][1], 3),
    )
