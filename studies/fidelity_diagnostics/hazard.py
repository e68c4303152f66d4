"""Diagnostic: per-source hazard of arrival by steps since the last departure, GS vs IALS."""

import sys

import numpy as np
import torch

torch.set_num_threads(1)
from ials_zoo.core.domains import get_domain
from ials_zoo.influence import fidelity as F
from ials_zoo.influence.multi import make_ials_parallel_env

env_id, policy, lr, epochs, steps = sys.argv[1], sys.argv[2], float(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
episodes = int(sys.argv[6]) if len(sys.argv) > 6 else 20
dom = get_domain(env_id)
agents = dom.agents()
watched = F.default_watched(dom, agents)
null = dom.null_influence


def hazards(us, K=12):
    """P(active at t | last active at t-k, inactive since), k = 2..K+1; and the mean first arrival."""
    at_risk = np.zeros(K + 2)
    hits = np.zeros(K + 2)
    first = []
    for u in us:
        for m in range(u.shape[1]):
            a = u[:, m] != null
            if a.any():
                first.append(int(np.argmax(a)))
            last = None
            for t in range(u.shape[0]):
                if last is not None and 2 <= t - last <= K + 1:
                    at_risk[t - last] += 1
                    hits[t - last] += a[t]
                if a[t]:
                    last = t
    return hits[2:] / np.maximum(at_risk[2:], 1), np.mean(first) if first else np.nan


gs_env = dom.parallel_env(learners=agents)
gs = F.run(gs_env, agents, watched, policy, episodes, 0, dom.n_actions)
gs_env.close()
aips = F.on_policy_aips(env_id, agents, policy, steps, 100_000, True, {}, lr, epochs, influence_lags=1, clock_horizon=0)
ie = make_ials_parallel_env(env_id, agents, predictor=aips, seed=0)
ia = F.run(ie, agents, watched, policy, episodes, 0, dom.n_actions)
ie.close()
np.set_printoptions(precision=3, suppress=True, linewidth=200)
for a in watched:
    hg, fg = hazards(gs.influence[a])
    hi, fi = hazards(ia.influence[a])
    mg = np.mean([F.episode_metrics(u, null)["arrivals"] for u in gs.influence[a]])
    mi = np.mean([F.episode_metrics(u, null)["arrivals"] for u in ia.influence[a]])
    print(a, f"arrivals GS {mg:.1f} IALS {mi:.1f}  first arrival GS {fg:.1f} IALS {fi:.1f}")
    print("  hazard by lag GS  ", hg[:10])
    print("  hazard by lag IALS", hi[:10])
