"""Traffic: how much of a lane's next arrival its AIP could know. Held-out cross-entropy of small
MLPs (one sigmoid per incoming lane) that predict u_t from: the d-set alone; the d-set and the
last draw (the default autoregressive AIP's input); the last 30 draws; the light's own state;
and, beyond any region's reach, the neighbouring lights' observations (occupancy and phase) of
the last 5 steps.

    python studies/fidelity_diagnostics/information.py POLICY STEPS EPOCHS HIDDEN

e.g. the IPPO lights, 100,000 GS steps, 10 epochs, 64 hidden units:

    python studies/fidelity_diagnostics/information.py leaderboard/policies/0f22715d32627b9c6b2e3a00514da869d8737da43dccfb7107d3949f8e7d985e.safetensors 100000 10 64
"""

import sys

import numpy as np
import torch

torch.set_num_threads(2)
from ials_zoo.core.domains import get_domain
from ials_zoo.evaluation import load_model
from ials_zoo.influence import fidelity as F
from ials_zoo.influence.dataset import collect_all

pol, steps, epochs, hidden = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
dom = get_domain("traffic_grid_v0")
agents = dom.agents()
actor = None if pol == "random" else F._PolicyActor(load_model(pol), agents, 100_000)
data = collect_all("traffic_grid_v0", agents, steps=steps, policy=actor, seed=100_000, progress=False)
N = 5  # the grid's side: tls_i sits at row i // 5, column i % 5


def neighbours(i):
    r, c = divmod(i, N)
    return [(r + dr) * N + c + dc for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)) if 0 <= r + dr < N and 0 <= c + dc < N]


def lag(x, k):  # [E, T, F] shifted k steps later, zeros before the episode's start
    y = np.zeros_like(x)
    y[:, k:] = x[:, :x.shape[1] - k]
    return y


def held_out_ce(X, U, seed=0):
    idx = np.random.default_rng(seed).permutation(X.shape[0])
    test, train = idx[:max(1, len(idx) // 10)], idx[max(1, len(idx) // 10):]
    flat = lambda a, i: torch.tensor(a[i].reshape(-1, a.shape[-1]), dtype=torch.float32)
    Xtr, Ytr, Xte, Yte = flat(X, train), flat(U, train), flat(X, test), flat(U, test)
    torch.manual_seed(seed)
    net = torch.nn.Sequential(torch.nn.Linear(X.shape[-1], hidden), torch.nn.ReLU(), torch.nn.Linear(hidden, 4))
    opt = torch.optim.Adam(net.parameters(), 3e-3)
    batch = 256
    total = epochs * -(-len(Xtr) // batch)
    schedule = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: max(0.0, 1 - s / total))
    for _ in range(epochs):
        perm = torch.randperm(len(Xtr))
        for b in range(0, len(Xtr), batch):
            j = perm[b:b + batch]
            opt.zero_grad()
            torch.nn.functional.binary_cross_entropy_with_logits(net(Xtr[j]), Ytr[j]).backward()
            opt.step()
            schedule.step()
    with torch.no_grad():
        return torch.nn.functional.binary_cross_entropy_with_logits(net(Xte), Yte, reduction="none").mean(0).numpy()


for a in ["tls_0", "tls_1", "tls_12"]:
    i = agents.index(a)
    full = data[a].dsets["full"].astype(np.float32)
    U = data[a].influences.astype(np.float32)
    d = full[..., :36]
    last = lag(U, 1)
    older = np.concatenate([lag(U, k) for k in range(2, 31)], -1)
    around = np.concatenate([lag(data[agents[j]].dsets["full"].astype(np.float32), k)
                             for j in neighbours(i) for k in range(5)], -1)
    rate = U.reshape(-1, 4).mean(0)
    print(f"{a}: entry rate per lane (the region's source order) {np.round(rate, 3)}, "
          f"entropy of that rate {np.round(-(rate * np.log(rate) + (1 - rate) * np.log(1 - rate)), 4)}")
    for name, X in {"d-set": d, "d-set, last draw (default)": np.concatenate([d, last], -1),
                    "d-set, last 30 draws": np.concatenate([d, last, older], -1),
                    "d-set, last draw, own light": np.concatenate([full, last], -1),
                    "d-set, last draw, neighbours' last 5 observations": np.concatenate([d, last, around], -1)}.items():
        ce = held_out_ce(X, U)
        print(f"  {name:52s} held-out cross-entropy per lane {np.round(ce, 4)}, mean {ce.mean():.4f}")
