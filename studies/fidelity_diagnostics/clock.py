"""Traffic, constant lights, the centre light tls_12 alone in its local simulator: does an AIP that
also reads the time since the episode's start (a clock, ``min(t, 100) / 100``) bring its cars at
the start of an episode when the GS does (see ``warm_up.py``)? MLPs with one sigmoid per lane
(hidden 128, lr 3e-3 decayed to 0, 30 epochs), reading the d-set and their last 3 draws, with
and without the clock, trained on 100,000 GS steps of the constant lights; then 30 LS episodes.

    python studies/fidelity_diagnostics/clock.py SEED
"""

import sys

import numpy as np
import torch

torch.set_num_threads(1)
from ials_zoo.core.domains import get_domain
from ials_zoo.influence import fidelity as F
from ials_zoo.influence.dataset import collect_all

seed = int(sys.argv[1])
dom = get_domain("traffic_grid_v0")
agents = dom.agents()
LAGS, HORIZON = 3, 100
data = collect_all("traffic_grid_v0", agents, steps=100_000, policy={a: (lambda obs: 0) for a in agents},
                   seed=seed + F.DATA_SEED_OFFSET, progress=False)["tls_12"]
D = data.dsets["dset"].astype(np.float32)
U = data.influences.astype(np.float32)
E, T = U.shape[:2]


def features(d, lags, t, clock):
    parts = [d, lags] + ([np.full(d.shape[:-1] + (1,), min(t, HORIZON) / HORIZON, np.float32)] if clock else [])
    return np.concatenate(parts, -1)


def train(clock):
    lags = np.zeros((E, T, 4 * LAGS), np.float32)
    for k in range(1, LAGS + 1):
        lags[:, k:, 4 * (k - 1):4 * k] = U[:, :-k]
    X = np.stack([features(D[:, t], lags[:, t], t, clock) for t in range(T)], 1)
    X, Y = torch.tensor(X.reshape(E * T, -1)), torch.tensor(U.reshape(E * T, 4))
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(X.shape[1], 128), torch.nn.ReLU(), torch.nn.Linear(128, 4))
    opt = torch.optim.Adam(net.parameters(), 3e-3)
    batch, epochs = 256, 30
    total = epochs * -(-len(X) // batch)
    schedule = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: max(0.0, 1 - s / total))
    for _ in range(epochs):
        perm = torch.randperm(len(X))
        for b in range(0, len(X), batch):
            j = perm[b:b + batch]
            opt.zero_grad()
            torch.nn.functional.binary_cross_entropy_with_logits(net(X[j]), Y[j]).backward()
            opt.step()
            schedule.step()
    return net


ls = dom.local_simulator(["tls_12"], n_envs=1)
for clock in (False, True):
    net = train(clock)
    rng = np.random.default_rng(seed)
    returns, firsts, blocks = [], [], []
    for ep in range(30):
        _, info = ls.reset(seed=seed * 1000 + ep)
        lags = np.zeros(4 * LAGS, np.float32)
        rewards, first = [], None
        for t in range(T):
            with torch.no_grad():
                p = torch.sigmoid(net(torch.tensor(features(info["dset"][0].astype(np.float32), lags, t, clock)))).numpy()
            u = (rng.random(4) < p).astype(np.int64)
            if first is None and u.any():
                first = t
            lags = np.concatenate([u.astype(np.float32), lags[:-4]])
            _, r, info = ls.step(np.zeros(1, np.int64), u[None])
            rewards.append(float(r[0]))
        returns.append(sum(rewards))
        firsts.append(first)
        blocks.append(np.add.reduceat(rewards, np.arange(0, T, 50)))
    print("clock" if clock else "no clock", "LS return", round(np.mean(returns), 1), "first arrival step mean",
          round(np.mean(firsts), 1), "min", min(firsts), "| reward by 50-step block", np.round(np.mean(blocks, 0), 1))
ls.close()
