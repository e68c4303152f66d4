"""Diagnostic: on held-out GS episodes (teacher forcing), does the traffic AIP's mean entry probability match the GS's entry rate?"""

import numpy as np
import torch

torch.set_num_threads(1)
from ials_zoo.core.domains import get_domain
from ials_zoo.influence import fidelity as F
from ials_zoo.influence.dataset import collect_all
from ials_zoo.influence.stacked import StackedPredictor

env = "traffic_grid_v0"
agents = get_domain(env).agents()
aips = F.on_policy_aips(env, agents, "random", 10_000, 100_001, True, {})
test = collect_all(env, agents, steps=3000, seed=7, progress=False)
sp = StackedPredictor([aips[a] for a in agents], 1)
E, T = test[agents[0]].influences.shape[:2]
p_sum = np.zeros((25, 4))
u_sum = np.zeros((25, 4))
for e in range(E):
    sp.reset()
    for t in range(T):
        d = np.stack([test[a].dsets["dset"][e, t] for a in agents])
        probs = sp.probs_padded(d)  # [25, 4, 2]
        u = np.stack([test[a].influences[e, t] for a in agents])
        sp.observe(u)
        p_sum += probs[:, :, 1]
        u_sum += u
for i in (0, 1, 12):
    print(
        f"tls_{i} per lane N,E,S,W: mean predicted {np.round(p_sum[i] / (E * T), 4)}  GS rate {np.round(u_sum[i] / (E * T), 4)}"
    )
print("all lights: predicted", round(p_sum.sum() / (E * T * 100), 4), "GS", round(u_sum.sum() / (E * T * 100), 4))
