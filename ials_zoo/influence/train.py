"""Train an approximate influence predictor on an :class:`InfluenceDataset` (paper §4.2).

The network is trained in torch and its weights copied into the numpy predictor classes of
``predictors.py``. Loss: the cross-entropy of each source's softmax head, averaged over the
sources (and over steps), i.e. the same quantity as :func:`evaluate_cross_entropy` reports.

Defaults, and why they differ from the SPEC's "Adam lr 1e-4": with lr 1e-4 the paper's
50,000-step data sets need thousands of updates to converge, so we keep Adam but use

* GRU: lr 2e-3, 120 epochs of 16-episode batches (whole episodes, hidden state zero at
  episode start). With 40 epochs the warehouse AIP still under-predicts neighbour visits
  and items live ~9% longer in the IALS than in the GS; with 120 about 3% (measured at a
  constant rate).
* MLP: lr 2e-3, 30 epochs of 256 shuffled single steps (the traffic loss is flat by then).
  Decayed, 2e-3 reaches the test cross-entropy a constant 1e-3 reached on the synthetic data
  of tests/test_influence.py (0.682 against 0.681; decayed 1e-3: 0.699).

The learning rate decays linearly to zero over training (``lr_schedule="constant"`` keeps it):
the last iterate of a constant rate miscalibrates rare classes (:func:`_scheduler`).
``lr``/``epochs`` can be set back to 1e-4 and more epochs. Training runs on one torch thread
(the nets are tiny; more threads only add overhead). The split is 90/10 by episode.
"""

from __future__ import annotations

import time

import numpy as np
from tqdm.auto import tqdm

from ials_zoo.core.domains import get_domain
from ials_zoo.core.extras import LR_SCHEDULES
from ials_zoo.core.region import check_dset_kind
from ials_zoo.core.streams import agent_key
from ials_zoo.errors import BadInput
from ials_zoo.influence.base import check_clock_horizon, clock_value, previous_influences, resolve_influence_lags
from ials_zoo.influence.predictors import (
    ARCHS,
    MarginalPredictor,
    UniformPredictor,
    cross_entropy_per_source,
    init_arrays,
)
from ials_zoo.runtime.processes import keep_freed_memory

DEFAULTS = {
    "gru": {"epochs": 120, "lr": 2e-3, "batch_episodes": 16, "hidden": 64},
    "mlp": {"epochs": 30, "lr": 2e-3, "batch_size": 256, "hidden": 64},
}



def _scheduler(opt, schedule: str, updates: int):
    """The learning rate over training: ``"linear"`` decays it to zero at the last update.

    Why: with a constant rate, Adam's last iterate wanders around the optimum, and a rare
    class's output bias wanders with it. Traffic MLPs trained at a constant 3e-3 predicted
    per-lane entry rates 12% off on average, up to 47%, on their own training data (tls_0 west
    0.066 against 0.090), with every light's mean right: the IALS then starves some lanes and
    floods others. Decayed linearly to zero, the same training is within 1.7% (max 7%), and its
    held-out cross-entropy is lower (0.1945 against 0.2047; docs/fidelity.md)."""
    import torch

    if schedule not in LR_SCHEDULES:
        raise BadInput(f"unknown lr schedule {schedule!r}; expected one of {list(LR_SCHEDULES)}")
    if schedule == "constant":
        return None
    total = max(int(updates), 1)
    return torch.optim.lr_scheduler.LambdaLR(opt, lambda k: max(0.0, 1.0 - k / total))


def _torch_modules():
    from ials_zoo.influence.torch_nets import TorchGRU, TorchMLP  # lazy: torch

    return {"mlp": TorchMLP, "gru": TorchGRU}


def _loss(logits, u, offsets):
    import torch.nn.functional as F

    # Mean over sources of each source's mean cross-entropy.
    total = 0.0
    M = len(offsets) - 1
    for m in range(M):
        total = total + F.cross_entropy(logits[:, offsets[m] : offsets[m + 1]], u[:, m])
    return total / M


def _fit(net, opt, X, U, batch: int, epochs: int, rng, offsets, bar, schedule: str = "linear") -> list[float]:
    """Adam on shuffled minibatches of ``X`` (episodes or steps) for ``epochs``, the learning
    rate following ``schedule`` (:func:`_scheduler`); returns the mean training loss of every
    epoch."""
    import torch

    scheduler = _scheduler(opt, schedule, epochs * -(-X.shape[0] // batch))
    history = []
    net.train()
    n_logits = offsets[-1]
    for _ in range(epochs):
        perm = torch.from_numpy(rng.permutation(X.shape[0]))
        running, count = 0.0, 0
        for start in range(0, X.shape[0], batch):
            idx = perm[start : start + batch]
            logits = net(X[idx])
            u = U[idx]
            loss = _loss(logits.reshape(-1, n_logits), u.reshape(-1, u.shape[-1]), offsets)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            if scheduler is not None:
                scheduler.step()
            running += loss.item() * len(idx)
            count += len(idx)
        history.append(running / max(count, 1))
        if bar is not None:
            bar.update(1)
            bar.set_postfix(loss=f"{history[-1]:.4f}")
    if bar is not None:
        bar.close()
    return history


def train_predictor(
    dataset,
    arch: str = "gru",
    dset_kind: str = "dset",
    epochs: int | None = None,
    seed: int = 0,
    progress: bool = True,
    lr: float | None = None,
    hidden: int | None = None,
    batch_size: int | None = None,
    test_fraction: float = 0.1,
    autoregressive: bool = False,
    lr_schedule: str = "linear",
    influence_lags: int | None = None,
    clock_horizon: int = 0,
):
    """Train an AIP of architecture ``arch`` (``"gru"`` or ``"mlp"``) on ``dataset``;
    ``autoregressive``: it also reads ``u_{t-1}`` (the recorded one: teacher forcing), or
    ``u_{t-1} .. u_{t-L}`` with ``influence_lags=L`` (None: 1; only for an autoregressive AIP).
    ``clock_horizon`` H > 0: it also reads the time since the episode's start, ``min(t, H) / H``.
    ``lr_schedule``: ``"linear"`` (to zero at the last update, the default) or ``"constant"``.

    Returns:
        ``(predictor, report)``. ``report`` (JSON-able) holds the hyper-parameters, the
        train/test episode counts, training wall-clock seconds and the cross-entropies
        (nats, see :func:`evaluate_cross_entropy`) on the train and test split of

        * ``trained`` -- the returned predictor,
        * ``untrained`` -- the same network at its random initialisation (seed ``seed``):
          the paper's untrained AIP,
        * ``uniform`` -- the domain's fixed class probabilities
          (``Domain.untrained_probs``, else uniform over classes),
        * ``marginal`` -- the empirical marginal ``P(u)`` of the training split;

        plus per-source test cross-entropies of the trained predictor.
    """
    import torch

    # Tiny networks: more threads only add synchronisation (and fight other processes).
    keep_freed_memory()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _train(dataset, arch, dset_kind, epochs, seed, progress, lr, hidden, batch_size, test_fraction,
                      autoregressive, lr_schedule, influence_lags, clock_horizon)
    finally:
        torch.set_num_threads(threads)


def hyperparameters(arch: str, epochs, lr, hidden, batch_size, min_epochs: int, lr_schedule: str = "linear") -> dict:
    """:data:`DEFAULTS` of ``arch`` with the given values in place of the defaults (the batch
    size counts episodes for a GRU, steps for an MLP)."""
    if lr_schedule not in LR_SCHEDULES:
        raise BadInput(f"unknown lr schedule {lr_schedule!r}; expected one of {list(LR_SCHEDULES)}")
    hp = dict(DEFAULTS[arch], lr_schedule=lr_schedule)
    for k, v in (("epochs", epochs), ("lr", lr), ("hidden", hidden)):
        if v is not None:
            hp[k] = v
    if batch_size is not None:
        hp["batch_episodes" if arch == "gru" else "batch_size"] = int(batch_size)
    if int(hp["epochs"]) < min_epochs:
        raise BadInput(f"epochs must be >= {min_epochs}, got {hp['epochs']}")
    return hp


def network_inputs(dataset, dset_kind: str, autoregressive: bool, influence_lags: int | None = None,
                   clock_horizon: int = 0) -> np.ndarray:
    """A data set's network inputs ``[E, T, D]`` (float32): the d-sets; for an autoregressive
    AIP the one-hot ``u_{t-1} .. u_{t-influence_lags}`` beside them (zeros before an episode's
    start); with ``clock_horizon`` H > 0 the clock ``min(t, H) / H`` last."""
    d = dataset.dsets[dset_kind].astype(np.float32)
    parts = [d]
    if autoregressive:
        offsets = np.concatenate([[0], np.cumsum(dataset.region.influence_classes)])
        lags = resolve_influence_lags(True, influence_lags)
        parts.append(previous_influences(dataset.influences, offsets, lags))
    if check_clock_horizon(clock_horizon):
        E, T = d.shape[:2]
        clock = clock_value(np.arange(T), clock_horizon).astype(np.float32)
        parts.append(np.broadcast_to(clock[None, :, None], (E, T, 1)))
    return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=2)


def _train(dataset, arch, dset_kind, epochs, seed, progress, lr, hidden, batch_size, test_fraction, autoregressive,
           lr_schedule, influence_lags, clock_horizon):
    import torch

    if arch not in ARCHS:
        raise BadInput(f"unknown AIP architecture {arch!r}; expected one of {sorted(ARCHS)}")
    check_dset_kind(dset_kind)
    influence_lags = resolve_influence_lags(autoregressive, influence_lags)
    clock_horizon = check_clock_horizon(clock_horizon)
    hp = hyperparameters(arch, epochs, lr, hidden, batch_size, min_epochs=0, lr_schedule=lr_schedule)
    if dataset.n_episodes < 2:
        raise BadInput(f"need at least 2 episodes to split train/test, got {dataset.n_episodes}")

    region = dataset.region
    train_idx, test_idx = dataset.split(test_fraction, seed=seed)
    d_all = network_inputs(dataset, dset_kind, autoregressive, influence_lags, clock_horizon)
    u_all = dataset.influences
    D = d_all.shape[2]
    offsets = [int(x) for x in np.concatenate([[0], np.cumsum(region.influence_classes)])]
    n_logits = offsets[-1]

    init = init_arrays(arch, D, int(hp["hidden"]), n_logits, seed)
    torch.manual_seed(seed)
    net = _torch_modules()[arch](D, int(hp["hidden"]), n_logits)
    net.load_numpy(init)
    opt = torch.optim.Adam(net.parameters(), lr=float(hp["lr"]))
    rng = np.random.default_rng(seed)

    if arch == "gru":
        X = torch.from_numpy(d_all[train_idx])  # [E, T, D]
        U = torch.from_numpy(u_all[train_idx])  # [E, T, M]
        batch = int(hp["batch_episodes"])
    else:
        X = torch.from_numpy(d_all[train_idx].reshape(-1, D))
        U = torch.from_numpy(u_all[train_idx].reshape(-1, region.n_sources))
        batch = int(hp["batch_size"])

    bar = None
    if progress:
        bar = tqdm(total=int(hp["epochs"]), desc=f"train {arch} AIP", unit="epoch")
    t0 = time.perf_counter()
    history = _fit(net, opt, X, U, batch, int(hp["epochs"]), rng, offsets, bar, lr_schedule)
    train_seconds = time.perf_counter() - t0

    kind = dict(dset_kind=dset_kind, autoregressive=autoregressive, influence_lags=influence_lags,
                clock_horizon=clock_horizon)
    return _trained_with_report(dataset, arch, hp, kind, (net.to_numpy(), init), (train_idx, test_idx),
                                (seed, test_fraction), train_seconds, history)


def _trained_with_report(dataset, arch: str, hp: dict, kind: dict, arrays: tuple, split: tuple, seeding: tuple,
                         train_seconds: float, history: list):
    """The trained predictor (``arrays``: its weights and its initial ones) and its report: its
    cross-entropies beside the untrained, uniform and marginal predictors'. ``kind``:
    ``dset_kind``, ``autoregressive``, ``influence_lags``, ``clock_horizon``."""
    region, (train_idx, test_idx), (seed, test_fraction) = dataset.region, split, seeding
    dset_kind, autoregressive = kind["dset_kind"], kind["autoregressive"]
    influence_lags, clock_horizon = kind["influence_lags"], kind["clock_horizon"]
    u_all = dataset.influences
    trained = ARCHS[arch](region, hidden=int(hp["hidden"]), arrays=arrays[0], **kind)
    untrained = ARCHS[arch](region, hidden=int(hp["hidden"]), arrays=arrays[1], **kind)
    uniform = UniformPredictor(region, dset_kind=dset_kind, probs=untrained_probs(region))
    marginal = MarginalPredictor.fit(dataset, dset_kind=dset_kind, episodes=train_idx)
    ce = _cross_entropies({"trained": trained, "untrained": untrained, "uniform": uniform, "marginal": marginal},
                          dataset, train_idx, test_idx)
    per_source = cross_entropy_per_source(trained, dataset, test_idx if len(test_idx) else train_idx)
    report = {
        "env_id": region.domain,
        "agent": region.agent,
        "arch": arch,
        "autoregressive": bool(autoregressive),
        **({"influence_lags": influence_lags} if autoregressive else {}),
        **({"clock_horizon": clock_horizon} if clock_horizon else {}),
        "dset_kind": dset_kind,
        "hyperparameters": {**hp, "optimizer": "Adam", "seed": int(seed), "test_fraction": test_fraction},
        "dataset": {
            "episodes": dataset.n_episodes,
            "steps": dataset.n_steps,
            "train_episodes": int(len(train_idx)),
            "test_episodes": int(len(test_idx)),
            "collect_seconds": dataset.metadata.get("collect_seconds"),
            "policy": dataset.metadata.get("policy"),
            "gs_options": dataset.metadata.get("gs_options", {}),
        },
        "train_seconds": round(train_seconds, 3),
        "loss_history": [round(x, 5) for x in history],
        "cross_entropy": ce,
        "test_cross_entropy_per_source": dict(zip(region.influence_names, map(float, per_source))),
        "marginal": [p.tolist() for p in MarginalPredictor.marginal_probs(u_all[train_idx], region.influence_classes)],
    }
    trained.metadata.update({k: v for k, v in report.items() if k != "loss_history"})
    trained.metadata["variant"] = "trained"
    return trained, report


def _cross_entropies(predictors: dict, dataset, train_idx, test_idx) -> dict:
    """``{name: {"train": CE, "test": CE or None}}`` (mean over sources) of each predictor."""
    return {name: {"train": float(np.mean(cross_entropy_per_source(pred, dataset, train_idx))),
                   "test": float(np.mean(cross_entropy_per_source(pred, dataset, test_idx))) if len(test_idx) else None}
            for name, pred in predictors.items()}


def untrained_probs(region):
    """The class probabilities of the domain's ``uniform`` AIP (``Domain.untrained_probs``),
    or ``None`` (uniform over classes) for a domain that sets none or is not registered."""
    try:
        return get_domain(region.domain).untrained_probs
    except ValueError:
        return None


def _reading(report: dict) -> str:
    """What an autoregressive AIP of a report reads besides the d-set ("" for a memoryless one)."""
    if not report.get("autoregressive"):
        return ""
    lags = int(report.get("influence_lags", 1))
    return ", reading its last draw" if lags == 1 else f", reading its last {lags} draws"


def format_report(report: dict) -> str:
    """A small text table of a :func:`train_predictor` report."""
    ce = report["cross_entropy"]
    lines = [
        f"AIP {report['arch']}{_reading(report)} ({report['dset_kind']!r} d-set) for "
        f"{report['env_id']}/{report['agent']}: "
        f"{report['dataset']['steps']} steps ({report['dataset']['train_episodes']} train / "
        f"{report['dataset']['test_episodes']} test episodes)",
        f"{'predictor':<12}{'train CE':>10}{'test CE':>10}   (nats, mean over sources)",
    ]
    for name in ("trained", "untrained", "uniform", "marginal"):
        tr, te = ce[name]["train"], ce[name]["test"]
        te_s = f"{te:>10.4f}" if te is not None else f"{'-':>10}"
        lines.append(f"{name:<12}{tr:>10.4f}{te_s}")
    cs = report["dataset"].get("collect_seconds")
    lines.append(
        f"collection: {cs if cs is not None else '-'} s   training: {report['train_seconds']} s "
        f"({report['hyperparameters']['epochs']} epochs, lr {report['hyperparameters']['lr']}, "
        f"{report['hyperparameters'].get('lr_schedule', 'constant')})"
    )
    return "\n".join(lines)




# --------------------------------------------------------------------------------------------
# Many agents at once


def _stacked_modules():
    from ials_zoo.influence.torch_nets import StackedGRU, StackedMLP  # lazy: torch

    return {"mlp": StackedMLP, "gru": StackedGRU}


def _initial_arrays(agent: str, old, arch: str, D: int, H: int, n_logits: int, dset_kind: str, autoregressive: bool,
                    seed: int, influence_lags: int = 0, clock_horizon: int = 0) -> dict:
    """The starting weights of ``agent``'s network: ``old``'s (a warm start, which must have the
    same shape and kind), else ``init_arrays`` seeded from ``seed`` and the agent's name."""
    if old is None:
        return init_arrays(arch, D, H, n_logits, seed=(seed * 1_000_003 + agent_key(agent)) % 2**32)
    lags = influence_lags
    if (old.name != arch or old.hidden != H or old.dset_kind != dset_kind or old.autoregressive != bool(autoregressive)
            or old.influence_lags != lags or old.clock_horizon != clock_horizon):
        raise BadInput(f"cannot warm-start a {arch} AIP (hidden {H}, autoregressive {bool(autoregressive)}, "
                       f"influence lags {lags}, clock horizon {clock_horizon}) from {old!r} (influence lags "
                       f"{old.influence_lags}, clock horizon {old.clock_horizon})")
    return {k: np.asarray(v, np.float32) for k, v in old._arrays().items()}


def _sources_by_classes(offsets) -> list[tuple]:
    """``[(k, sources, logit indices [sources, k])]``: the sources grouped by their class count, so
    that one cross-entropy call covers each group (a region of ingolstadt21 has ~150 sources of
    two or three classes; a call per source dominated the AIPs' training)."""
    import torch

    sizes = np.diff(offsets)
    out = []
    for k in sorted(set(sizes.tolist())):
        sources = np.nonzero(sizes == k)[0]
        logits = np.asarray(offsets)[sources][:, None] + np.arange(k)[None, :]
        out.append((int(k), torch.from_numpy(sources), torch.from_numpy(logits)))
    return out


def _fit_stacked(net, opt, X, U, batch: int, epochs: int, rngs, offsets, bar, schedule: str = "linear") -> None:
    """Adam on every agent's own shuffled minibatches (``X [G, items, ...]``, one generator per
    agent): the loss is the sum of the agents' mean cross-entropies, so each network's
    gradient is its own. The learning rate follows ``schedule`` (:func:`_scheduler`)."""
    import torch

    G, n_items, n_logits = X.shape[0], X.shape[1], offsets[-1]
    scheduler = _scheduler(opt, schedule, epochs * -(-n_items // batch))
    gi = torch.arange(G)[:, None]
    by_classes = _sources_by_classes(offsets)
    for _ in range(epochs):
        perm = torch.from_numpy(np.stack([r.permutation(n_items) for r in rngs]))
        for start in range(0, n_items, batch):
            idx = perm[:, start:start + batch]
            flat = net(X[gi, idx]).reshape(G, -1, n_logits)
            u = U[gi, idx].reshape(G, -1, U.shape[-1])
            loss = 0.0
            for k, sources, logits in by_classes:  # every source of k classes in one call
                lm = flat[:, :, logits]  # [G, batch, sources, k]
                ce = torch.nn.functional.cross_entropy(lm.reshape(-1, k), u[:, :, sources].reshape(-1),
                                                       reduction="none").reshape(G, -1, len(sources))
                loss = loss + ce.mean(dim=1).sum(dim=1)
            loss = (loss / (len(offsets) - 1)).sum()  # the agents' losses are independent
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            if scheduler is not None:
                scheduler.step()
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()


def train_predictors(datasets: dict, arch: str, hidden: int | None = None, lr: float | None = None,
                     epochs: int | None = None, batch_size: int | None = None, seed: int = 0,
                     init: dict | None = None, dset_kind: str = "dset", test_fraction: float = 0.1,
                     progress: bool = False, autoregressive: bool = False,
                     lr_schedule: str = "linear", influence_lags: int | None = None,
                     clock_horizon: int = 0) -> tuple[dict, dict]:
    """Train one AIP per agent on its own data, all in one stacked torch program.

    Every agent's network is a slice of stacked weights; the loss is the sum of the agents'
    losses and Adam works element-wise, so this is exactly training each network alone on its
    own data, in one batched computation per update (the agents' data sets come from one GS
    run: same episodes, same length). Regions of different shapes (a real network's junctions)
    are trained in groups of one shape each (:func:`_train_by_shape`). ``init``
    (``{agent: predictor}``) warm-starts from those
    networks (DIALS retrains its AIPs), else each starts from ``init_arrays`` seeded from
    ``seed`` and the agent's name. ``autoregressive``: every AIP also reads ``u_{t-1}`` (teacher
    forcing), or ``u_{t-1} .. u_{t-L}`` with ``influence_lags=L``; ``clock_horizon`` as for
    :func:`train_predictor`. ``lr_schedule`` as for :func:`train_predictor`. Returns
    ``({agent: predictor}, report)`` with each agent's train/test
    cross-entropy and the training seconds.
    """
    if arch not in ARCHS:
        raise BadInput(f"unknown AIP architecture {arch!r}; expected one of {sorted(ARCHS)}")
    agents = list(datasets)
    if not agents:
        raise BadInput("no data sets to train on")
    first = datasets[agents[0]]
    if any(datasets[a].n_steps != first.n_steps for a in agents):
        raise BadInput("the data sets differ in length; collect them in one GS run")
    if len({_shape(datasets[a], dset_kind) for a in agents}) > 1:
        return _train_by_shape(datasets, arch, hidden=hidden, lr=lr, epochs=epochs, batch_size=batch_size, seed=seed,
                               init=init, dset_kind=dset_kind, test_fraction=test_fraction, progress=progress,
                               autoregressive=autoregressive, lr_schedule=lr_schedule,
                               influence_lags=influence_lags, clock_horizon=clock_horizon)
    hp = hyperparameters(arch, epochs, lr, hidden, batch_size, min_epochs=1, lr_schedule=lr_schedule)
    influence_lags = resolve_influence_lags(autoregressive, influence_lags)
    clock_horizon = check_clock_horizon(clock_horizon)
    region = first.region
    offsets = [int(x) for x in np.concatenate([[0], np.cumsum(region.influence_classes)])]
    n_logits, H = offsets[-1], int(hp["hidden"])
    inputs = {a: network_inputs(datasets[a], dset_kind, autoregressive, influence_lags, clock_horizon)
              for a in agents}
    D = inputs[agents[0]].shape[2]
    train_idx, test_idx = first.split(test_fraction, seed=seed)
    arrays = [_initial_arrays(a, (init or {}).get(a), arch, D, H, n_logits, dset_kind, autoregressive, seed,
                              influence_lags, clock_horizon) for a in agents]
    X = np.stack([inputs[a][train_idx] for a in agents])
    U = np.stack([datasets[a].influences[train_idx] for a in agents])
    net, seconds = _fit_group(arch, arrays, X, U, hp, [agent_key(a) for a in agents], seed, offsets, progress,
                              lr_schedule)
    kind = dict(dset_kind=dset_kind, autoregressive=autoregressive, influence_lags=influence_lags,
                clock_horizon=clock_horizon)
    out, ce = _stacked_predictors(net, datasets, arch, hp, seed, seconds, test_idx if len(test_idx) else train_idx,
                                  kind)
    return out, {"arch": arch, "autoregressive": bool(autoregressive),
                 **({"influence_lags": influence_lags} if autoregressive else {}), "hyperparameters": hp, "agents": len(agents), "train_seconds": round(seconds, 3),
                 "test_cross_entropy": ce, "mean_test_cross_entropy": float(np.mean(list(ce.values()))),
                 "warm_start": bool(init)}


def _fit_group(arch: str, arrays: list, X: np.ndarray, U: np.ndarray, hp: dict, keys: list, seed: int, offsets,
               progress: bool, lr_schedule: str):
    """The stacked network of ``arrays`` fitted to inputs ``X`` and influences ``U`` (``[G, episodes,
    T, ...]``), one thread; returns it and the seconds the fit took. ``keys``: each member's
    stream (its agent's name)."""
    import torch

    keep_freed_memory()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        torch.manual_seed(seed)
        net = _stacked_modules()[arch](arrays)
        opt = torch.optim.Adam(net.parameters(), lr=float(hp["lr"]))
        X, U = torch.from_numpy(X), torch.from_numpy(U)
        G = len(keys)
        if arch == "mlp":
            X, U = X.reshape(G, -1, X.shape[-1]), U.reshape(G, -1, U.shape[-1])
            batch = int(hp["batch_size"])
        else:
            batch = int(hp["batch_episodes"])
        rngs = [np.random.default_rng([seed, k]) for k in keys]
        bar = None
        if progress:
            bar = tqdm(total=int(hp["epochs"]), desc=f"train {G} {arch} AIPs", unit="epoch")
        t0 = time.perf_counter()
        _fit_stacked(net, opt, X, U, batch, int(hp["epochs"]), rngs, offsets, bar, lr_schedule)
        return net, time.perf_counter() - t0
    finally:
        torch.set_num_threads(threads)


def _stacked_predictors(net, datasets: dict, arch: str, hp: dict, seed: int, seconds: float, test_idx,
                        kind: dict) -> tuple[dict, dict]:
    """Every agent's trained predictor out of the stacked ``net`` (its slice), with its metadata,
    and its held-out cross-entropy. ``kind``: ``dset_kind``, ``autoregressive``,
    ``influence_lags``, ``clock_horizon``."""
    out, ce = {}, {}
    for g, (a, data) in enumerate(datasets.items()):
        pred = ARCHS[arch](data.region, hidden=int(hp["hidden"]), arrays=net.arrays(g), **kind)
        test = cross_entropy_per_source(pred, data, test_idx)
        pred.metadata.update({"variant": "trained", "arch": arch, "autoregressive": bool(kind["autoregressive"]),
                              **({"influence_lags": kind["influence_lags"]} if kind["autoregressive"] else {}),
                              **({"clock_horizon": kind["clock_horizon"]} if kind["clock_horizon"] else {}),
                              "hyperparameters": {**hp, "seed": int(seed)},
                              "dataset": {"steps": data.n_steps, "collect_seconds": data.metadata.get("collect_seconds"),
                                          "policy": data.metadata.get("policy")},
                              "train_seconds": round(seconds, 3), "test_cross_entropy": float(np.mean(test))})
        out[a] = pred
        ce[a] = float(np.mean(test))
    return out, ce


def _shape(dataset, dset_kind: str) -> tuple:
    return (tuple(dataset.region.influence_classes), dataset.region.dset_size(dset_kind))


def _train_by_shape(datasets: dict, arch: str, **settings) -> tuple[dict, dict]:
    """:func:`train_predictors` over regions of several shapes: one stacked training per shape,
    the predictors back in the agents' order and one report (seconds summed)."""
    groups: dict[tuple, dict] = {}
    for a, d in datasets.items():
        groups.setdefault(_shape(d, settings["dset_kind"]), {})[a] = d
    preds, ce, seconds, report = {}, {}, 0.0, {}
    for group in groups.values():
        init = {a: p for a, p in (settings["init"] or {}).items() if a in group} or None
        out, report = train_predictors(group, arch, **{**settings, "init": init})
        preds.update(out)
        ce.update(report["test_cross_entropy"])
        seconds += report["train_seconds"]
    return ({a: preds[a] for a in datasets},
            dict(report, agents=len(datasets), train_seconds=round(seconds, 3), groups=len(groups),
                 test_cross_entropy={a: ce[a] for a in datasets}, mean_test_cross_entropy=float(np.mean(list(ce.values()))),
                 warm_start=bool(settings["init"])))


__all__ = ["DEFAULTS", "LR_SCHEDULES", "format_report", "train_predictor", "train_predictors"]
