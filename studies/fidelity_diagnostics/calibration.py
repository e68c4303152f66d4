"""Diagnostic: does a traffic AIP's mean entry probability match the GS's entry rate, lane by lane,
on the GS data it was trained on and on held-out GS episodes (teacher forcing)?

    python studies/fidelity_diagnostics/calibration.py linear     # the default lr schedule
    python studies/fidelity_diagnostics/calibration.py constant   # the constant rate used before
"""

import sys

import numpy as np
import torch

torch.set_num_threads(1)
from ials_zoo.core.domains import get_domain
from ials_zoo.influence import fidelity as F
from ials_zoo.influence.dataset import collect_all
from ials_zoo.influence.metrics import evaluate_cross_entropy

schedule = sys.argv[1] if len(sys.argv) > 1 else "linear"
env = "traffic_grid_v0"
agents = get_domain(env).agents()
# the same data and seed as on_policy_aips uses for `ials-zoo fidelity --seed 1`'s first training
train = collect_all(env, agents, steps=10_000, seed=100_001, progress=False)
aips = F.on_policy_aips(env, agents, "random", 10_000, 100_001, True, {}, lr_schedule=schedule, influence_lags=1, clock_horizon=0)
test = collect_all(env, agents, steps=3000, seed=7, progress=False)


def mean_probability(pred, data):
    """Per lane: the AIP's mean entry probability and the GS's entry rate (teacher forcing)."""
    d, u = data.dsets["dset"], data.influences
    E, T, M = u.shape
    pred.reset(E)
    p_sum = np.zeros(M)
    for t in range(T):
        p_sum += pred.probs_padded(d[:, t])[:, :, 1].sum(axis=0)
        pred.observe(u[:, t])
    return p_sum / (E * T), u.mean(axis=(0, 1))


print(f"lr schedule {schedule}")
for name, data in (("training data", train), ("held-out", test)):
    err = []
    for a in agents:
        p, g = mean_probability(aips[a], data[a])
        err.append(np.abs(np.log(p / g)))
        if a in ("tls_0", "tls_1", "tls_12"):
            print(f"  {name}: {a} per lane N,E,S,W: mean predicted {np.round(p, 4)}  GS rate {np.round(g, 4)}")
    err = np.array(err)
    print(f"  {name}: |log(predicted / GS rate)| over the 100 lanes: mean {err.mean():.3f}, max {err.max():.3f}")
ce = np.mean([evaluate_cross_entropy(aips[a], test[a]) for a in agents])
print(f"  held-out cross-entropy, mean over the 25 AIPs: {ce:.4f}")
