"""Traffic, constant lights: the start of the episode at the centre light tls_12, GS vs IALS. The
grid starts empty, so on the GS no car reaches an inner light for a while; the AIPs (an MLP
reading the d-set and its last draws) have no clock and cannot tell an early empty lane from a
late one. Prints the return, the steps with no car (reward 0), the first arrival's step, and the
reward and arrivals per 50-step block, over 30 episodes (GS seeds SEED * 1000 + episode).

    python studies/fidelity_diagnostics/warm_up.py SEED

(the AIPs: the fidelity report's defaults before traffic's AIPs read a clock, i.e. without one,
trained on the data of ``ials-zoo fidelity --seed SEED``).
"""

import sys

import numpy as np
import torch

torch.set_num_threads(1)
from ials_zoo.core.domains import get_domain
from ials_zoo.influence import fidelity as F
from ials_zoo.influence.multi import make_ials_parallel_env

seed = int(sys.argv[1])
dom = get_domain("traffic_grid_v0")
agents = dom.agents()


def rewards(env, episodes=30):
    """``[episodes, T, 5]``: tls_12's reward and its 4 influence bits at every step."""
    out = []
    for ep in range(episodes):
        env.reset(seed=seed * 1000 + ep)
        steps = []
        while env.agents:
            _, reward, _, _, infos = env.step({a: 0 for a in agents})
            steps.append([reward["tls_12"], *infos["tls_12"]["influence"]])
        out.append(np.array(steps))
    return np.stack(out)


gs_env = dom.parallel_env(learners=agents)
gs = rewards(gs_env)
gs_env.close()
aips = F.on_policy_aips("traffic_grid_v0", agents, "constant", 100_000, seed + F.DATA_SEED_OFFSET, True, {}, clock_horizon=0)
ials_env = make_ials_parallel_env("traffic_grid_v0", agents, predictor=aips, seed=seed)
ials = rewards(ials_env)
ials_env.close()
for name, x in (("GS", gs), ("IALS", ials)):
    r, u = x[..., 0], x[..., 1:]
    first = [np.flatnonzero(u[e].sum(1))[0] for e in range(len(u)) if u[e].sum()]
    print(name, "return", r.sum(1).mean().round(1), "steps with reward 0:", (r == 0).sum(1).mean().round(1),
          "first arrival step mean", np.mean(first).round(1), "min", np.min(first),
          "| reward by 50-step block", np.round(r.reshape(len(r), 6, 50).sum(2).mean(0), 1),
          "| arrivals by block", np.round(u.sum(2).reshape(len(u), 6, 50).sum(2).mean(0), 1))
