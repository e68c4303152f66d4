"""How long the on-policy AIPs of every agent take to train on 10,000 GS steps: DIALS's budget vs the
fidelity report's learning rate and epochs, both reading their last draw (traffic's fidelity AIPs
now also learn from 100,000 steps and read 3 draws: about ten times this training)."""

import sys
import time

import torch

torch.set_num_threads(1)
from ials_zoo.core.domains import get_domain
from ials_zoo.core.extras import dials_of
from ials_zoo.influence.dataset import collect_all
from ials_zoo.influence.train import train_predictors

env = sys.argv[1]
dom = get_domain(env)
d = dials_of(dom)
agents = dom.agents()
t = time.perf_counter()
data = collect_all(env, agents, steps=10_000, seed=100_000, progress=False)
tc = time.perf_counter() - t
print(env, f"collect 10,000 GS steps: {tc:.1f} s")
for lr, ep, schedule in (
    (d.lr_for(True), d.aip_epochs, d.aip_lr_schedule),
    (d.fidelity_aip_lr, d.fidelity_aip_epochs, d.fidelity_aip_lr_schedule),
):
    t = time.perf_counter()
    _, r = train_predictors(
        data,
        d.aip_arch,
        hidden=d.aip_hidden,
        lr=lr,
        epochs=ep,
        batch_size=d.aip_batch,
        seed=100_000,
        autoregressive=True,
        lr_schedule=schedule,
    )
    print(
        env,
        f"lr {lr:g} x {ep} epochs: {time.perf_counter() - t:.1f} s, mean test CE {r['mean_test_cross_entropy']:.4f}",
        flush=True,
    )
