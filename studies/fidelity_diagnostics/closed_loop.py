"""The traffic LS fed several kinds of influence, the IPPO lights acting on the LS's own
observations (closed loop): the return of tls_0 / tls_1 / tls_12 against the GS's.

Rows: ``gs`` (the GS), ``replay`` (the LS fed the GS's recorded cars, the lights replaying the
GS's actions), ``closed`` (the same cars, the lights acting), ``other_episode`` (each lane's cars
from another GS episode: platoons kept, their timing against this episode lost), ``bernoulli``
(independent arrivals at each lane's rate in this episode: platoons lost), and, with STEPS > 0
(GS steps of the IPPO lights to learn from): ``ngramK`` (arrivals drawn from their own last K
arrivals and the time of the episode, counted on that data; no d-set) and ``mlp_lagsK`` (an MLP
AIP reading the d-set and its last K draws, trained on the first TRAIN_STEPS of that data; like
the one ``ials-zoo fidelity --aip-influence-lags K`` trains, with one sigmoid per lane instead of
a two-class softmax), each with its mean arrivals per episode.

    python studies/fidelity_diagnostics/closed_loop.py POLICY EPISODES [STEPS TRAIN_STEPS]

e.g. ``... closed_loop.py leaderboard/policies/0f22715d32627b9c6b2e3a00514da869d8737da43dccfb7107d3949f8e7d985e.safetensors 30 100000 10000``
(and ``... 100000 100000``).
"""

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


def joint(obs):
    """The watched lights' observations in the joint policy's 25 rows (the others zero)."""
    full = np.zeros((25, obs.shape[1]), np.float32)
    full[idx] = obs
    return full


def start(ep):
    """Reset the LS and the policy for episode ``ep``: the frame stack, the policy's first input
    and the LS's info."""
    obs, info = ls.reset(seed=ep)
    policy.reset(ep)
    fs = FrameStack(getattr(policy, "frame_stack", 1))
    return fs, fs.reset(joint(obs)), info


def closed_loop(ep, u):
    """The policy acting on the LS's own observations, the LS fed the influence ``u`` [T, 3, 4]."""
    fs, x, _ = start(ep)
    ret = np.zeros(3)
    sw = np.zeros(3)
    for t in range(len(u)):
        acts = policy.act_all(x)[idx]
        obs, r, _ = ls.step(np.asarray(acts, np.int64), u[t].astype(np.int64))
        ret += r
        sw += acts
        x = fs.step(joint(obs))
    return ret, sw


res = {"gs": [], "replay": [], "closed": [], "sw_gs": [], "sw_closed": [], "other_episode": [], "bernoulli": []}
for ep, rec in enumerate(records):
    # replay: GS actions
    ls.reset(seed=ep)
    ret = np.zeros(3)
    for t in range(len(rec["u"])):
        _, r, _ = ls.step(np.asarray(rec["a"][t], np.int64), rec["u"][t].astype(np.int64))
        ret += r
    res["replay"].append(ret)
    ret, sw = closed_loop(ep, np.stack(rec["u"]))
    res["closed"].append(ret)
    res["gs"].append(rec["r"])
    res["sw_gs"].append(rec["switch"])
    res["sw_closed"].append(sw)
    # the same lanes' arrivals from other episodes: platoons kept, their timing against this episode lost
    other = np.stack([np.stack(records[(ep + 1 + lane) % episodes]["u"])[:, :, lane] for lane in range(4)], -1)
    res["other_episode"].append(closed_loop(ep, other)[0])
    # independent arrivals at each lane's rate in this episode: platoons lost too
    u = np.stack(rec["u"])
    rng = np.random.default_rng(ep)
    res["bernoulli"].append(closed_loop(ep, (rng.random(u.shape) < u.mean(0, keepdims=True)).astype(np.int64))[0])


def ngram(k, buckets=6):
    """Per watched lane, P(u_t = 1 | u_{t-k..t-1}, t // (T / buckets)) counted on the GS data."""
    tables = []
    for a in watch:
        U = z[f"{a}_u"]
        E, T, L = U.shape
        tab = np.zeros((L, buckets, 2 ** k, 2)) + 0.5
        for e in range(E):
            for lane in range(L):
                ctx = 0
                for t in range(T):
                    tab[lane, t * buckets // T, ctx, U[e, t, lane]] += 1
                    ctx = ((ctx << 1) | int(U[e, t, lane])) & (2 ** k - 1)
        tables.append(tab[..., 1] / tab.sum(-1))
    return np.stack(tables)  # [3, L, buckets, 2^k]


def sample(p, T, rng, buckets=6):
    A, L = p.shape[:2]
    u = np.zeros((T, A, L), np.int64)
    ctx = np.zeros((A, L), np.int64)
    for t in range(T):
        q = p[np.arange(A)[:, None], np.arange(L)[None], t * buckets // T, ctx]
        u[t] = rng.random((A, L)) < q
        ctx = ((ctx << 1) | u[t]) & (p.shape[-1] - 1)
    return u


def lags(U, K):
    out = []
    for k in range(1, K + 1):
        y = np.zeros_like(U)
        y[:, k:] = U[:, :-k]
        out.append(y)
    return np.concatenate(out, -1) if out else U[..., :0]


def train(a, K, seed=0):
    U = z[f"{a}_u"][:n_train_eps].astype(np.float32)
    D = z[f"{a}_full"][:n_train_eps, :, :36].astype(np.float32)
    X = torch.tensor(np.concatenate([D, lags(U, K)], -1).reshape(-1, 36 + 4 * K))
    Y = torch.tensor(U.reshape(-1, 4))
    torch.manual_seed(seed)
    net = torch.nn.Sequential(torch.nn.Linear(X.shape[1], HIDDEN), torch.nn.ReLU(), torch.nn.Linear(HIDDEN, 4))
    opt = torch.optim.Adam(net.parameters(), 3e-3)
    bs = 256
    total = EPOCHS * ((len(X) + bs - 1) // bs)
    sch = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: max(0.0, 1 - s / total))
    for _ in range(EPOCHS):
        perm = torch.randperm(len(X))
        for b in range(0, len(X), bs):
            j = perm[b:b + bs]
            opt.zero_grad()
            torch.nn.functional.binary_cross_entropy_with_logits(net(X[j]), Y[j]).backward()
            opt.step()
            sch.step()
    return net


def ials_episode(ep, nets, K, rng):
    fs, x, info = start(ep)
    hist = np.zeros((3, 4 * K), np.float32)
    ret, arr = np.zeros(3), np.zeros(3)
    for t in range(300):
        with torch.no_grad():
            x_in = np.concatenate([info["dset"].astype(np.float32), hist], 1)
            p = np.stack([torch.sigmoid(nets[i](torch.tensor(x_in[i]))).numpy() for i in range(3)])
        u = (rng.random(p.shape) < p).astype(np.int64)
        if K:
            hist = np.concatenate([u.astype(np.float32), hist[:, :-4]], 1)
        acts = policy.act_all(x)[idx]
        obs, r, info = ls.step(np.asarray(acts, np.int64), u)
        ret += r
        arr += u.sum(1)
        x = fs.step(joint(obs))
    return ret, arr


if len(sys.argv) > 3:
    from ials_zoo.influence.dataset import collect_all
    from ials_zoo.influence.fidelity import _PolicyActor

    steps, train_steps = int(sys.argv[3]), int(sys.argv[4])
    data = collect_all("traffic_grid_v0", agents, steps=steps, policy=_PolicyActor(policy, agents, 100_000),
                       seed=100_000, progress=False)
    z = {f"{a}_u": data[a].influences for a in watch} | {f"{a}_full": data[a].dsets["full"] for a in watch}
    n_train_eps = -(-train_steps // data[watch[0]].influences.shape[1])
    EPOCHS, HIDDEN = 30, 128

    for k in (0, 3, 6):
        p = ngram(k)
        rng = np.random.default_rng(1000 + k)
        res[f"ngram{k}"] = [closed_loop(ep, sample(p, len(records[ep]["u"]), rng))[0] for ep in range(episodes)]
        res[f"ngram{k}_arrivals"] = [sample(p, 300, rng).sum((0, 2)) for ep in range(episodes)]
    for K in (1, 3):
        nets = [train(a, K) for a in watch]
        rng = np.random.default_rng(K)
        out = [ials_episode(ep, nets, K, rng) for ep in range(episodes)]
        res[f"mlp_lags{K}"] = [o[0] for o in out]
        res[f"mlp_lags{K}_arrivals"] = [o[1] for o in out]
res["gs_arrivals"] = [np.stack(r["u"]).sum((0, 2)) for r in records]
for k in res:
    v = np.array(res[k])
    print(k, "mean", np.round(v.mean(0), 1), "sd", np.round(v.std(0), 1))
ls.close()
