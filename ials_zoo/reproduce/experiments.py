"""What the jobs of ``ials-zoo reproduce`` do (each runs in its own worker process).

* :func:`train_aip` -- Algorithm 1 + AIP training with the project's own ``collect`` and
  ``train_predictor``, timed here; writes ``aip.pt`` (its metadata carries the measured
  collection and training seconds, which ``ppo_single`` adds to the wall-clock) and
  ``marginal.pt`` (F-IALS with the empirical marginal of the same data, charged the same
  collection time).
* :func:`joint_reference` -- every agent acting with a scripted / random policy on the GS
  (the multi-agent track's references).
* :func:`item_lifetimes`, :func:`record_item_ages`, :func:`lifetime_histograms` -- how long
  items stay on the shelves in the GS vs an IALS (paper §5.4).
* :func:`off_policy_cross_entropy`, :func:`dset_ablation` -- the d-set vs full-history AIP,
  tested on data from another policy (paper §4.2).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ials_zoo.core.domains import get_domain
from ials_zoo.core.extras import study_of
from ials_zoo.errors import BadInput
from ials_zoo.influence.constant import MarginalPredictor, UniformPredictor
from ials_zoo.influence.dataset import collect
from ials_zoo.influence.files import save_predictor
from ials_zoo.influence.ials import make_ials
from ials_zoo.influence.metrics import evaluate_cross_entropy
from ials_zoo.influence.networks import untrained_predictor
from ials_zoo.influence.train import train_predictor, untrained_probs
from ials_zoo.leaderboard.build import result_for
from ials_zoo.utils import atomic_path, atomic_write_text


def _study_training(arch: str) -> dict:
    """The AIP training of the paper's study as it was measured (leaderboard/reproduction.md): a constant
    learning rate, the MLP's at 1e-3 (the trainer's defaults have since moved to a decaying rate
    and 2e-3), so a re-run reproduces the reports."""
    return {"lr_schedule": "constant", "lr": 1e-3 if arch == "mlp" else None}


def _write_json(path: Path, data) -> None:
    atomic_write_text(path, json.dumps(data, indent=2, default=str) + "\n")


# --------------------------------------------------------------------------------------------
# AIPs


def train_aip(env_id: str, agent: str, out_dir, steps: int = 50_000, epochs: int | None = None,
              seed: int = 0, options: dict | None = None, arch: str | None = None,
              dset_kind: str = "dset", workers: int = 1) -> dict:
    """Collect ``steps`` steps (uniform random learner, scripted neighbours) with ``workers``
    GS processes, train an AIP, save ``aip.pt``, ``marginal.pt`` and ``report.json`` (written
    last: the done marker)."""

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    arch = arch or get_domain(env_id).default_predictor
    t0 = time.perf_counter()
    data = collect(env_id, agent, steps=steps, seed=seed, gs_options=dict(options or {}), progress=False,
                   workers=workers)
    collect_wall = time.perf_counter() - t0
    pred, report = train_predictor(data, arch=arch, dset_kind=dset_kind, epochs=epochs, seed=seed,
                                   progress=False, **_study_training(arch))
    save_predictor(pred, out / "aip.pt")
    train_idx, _ = data.split(0.1, seed=seed)
    marg = MarginalPredictor.fit(data, dset_kind=dset_kind, episodes=train_idx)
    # Fitting a marginal is counting, but it needs the same collected data: charge that time.
    marg.metadata.update({"variant": "marginal", "dataset": {"collect_seconds": data.metadata["collect_seconds"]},
                          "train_seconds": 0.0})
    save_predictor(marg, out / "marginal.pt")
    report = dict(report, collect_wall_seconds=round(collect_wall, 3), collect_workers=workers,
                  options=dict(options or {}))
    _write_json(out / "report.json", report)
    return report


def joint_reference(params: dict, out_dir) -> dict:
    """Every agent of ``params["env_id"]`` acting with a reference policy (``scripted`` or
    ``random``) on the GS with the protocol's seeds: the multi-agent track's references.
    Writes ``result.json``."""

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    result = result_for(params["env_id"], None, params["policy"], params["episodes"], joint=True,
                        notes="ials-zoo reproduce (dials): every agent acting with this reference policy")
    _write_json(out / "result.json", result)
    return result


# --------------------------------------------------------------------------------------------
# Item lifetimes (memory experiment)


def item_lifetimes(ages) -> list[int]:
    """Lifetimes of the items in an episode of item ages ``ages[T, K]`` (0 = no item; an
    item's age counts the observations it has been visible in, as in the warehouse).

    An item ends at row ``t`` when the cell's age does not go on to ``ages[t] + 1`` at row
    ``t + 1``; its lifetime is then ``ages[t]`` (the number of observations it was visible
    in). Items still present in the last row are censored and left out."""
    a = np.asarray(ages)
    if a.ndim != 2:
        raise BadInput(f"ages must have shape [T, K], got {a.shape}")
    if a.size and (a < 0).any():
        raise BadInput("ages must be >= 0")
    cur, nxt = a[:-1], a[1:]
    ended = (cur > 0) & (nxt != cur + 1)
    return sorted(int(x) for x in cur[ended])


def record_item_ages(env_id: str, agent: str, simulator: str = "gs", episodes: int = 10,
                     seed: int = 0, policy=None, **options) -> list[np.ndarray]:
    """Item ages ``[T+1, K]`` of ``agent``'s region per episode, in the GS
    (``simulator="gs"``) or an IALS (``simulator`` = a predictor spec for ``make_ials``), for a
    domain with ``study_of(domain).lifetime_probes`` (the warehouse). ``policy``: ``obs -> action``
    (default uniform random)."""

    domain = get_domain(env_id)
    if study_of(domain).lifetime_probes is None:
        raise BadInput(f"{env_id} has no items whose lifetimes could be measured "
                         "(its StudySettings.lifetime_probes is not set)")
    gs_probe, ls_probe = study_of(domain).lifetime_probes
    rng = np.random.default_rng(seed)
    act = policy or (lambda obs: int(rng.integers(domain.n_actions)))
    out = []
    if simulator == "gs":
        env = domain.parallel_env(learners=[agent], **options)
        try:
            for ep in range(episodes):
                obs, _ = env.reset(seed=seed + ep)
                rows = [gs_probe(env, agent)]
                while env.agents:
                    obs, *_ = env.step({agent: act(obs[agent])})
                    rows.append(gs_probe(env, agent))
                out.append(np.stack(rows))
        finally:
            env.close()
        return out

    env = make_ials(env_id, agent, predictor=simulator, seed=seed, **options)
    try:
        for ep in range(episodes):
            obs, _ = env.reset(seed=seed + ep)
            rows = [ls_probe(env.ls)]
            done = False
            while not done:
                obs, _, term, trunc, _ = env.step(act(obs))
                rows.append(ls_probe(env.ls))
                done = term or trunc
            out.append(np.stack(rows))
    finally:
        env.close()
    return out


def lifetime_histograms(env_id: str, agent: str, simulators: dict, episodes: int = 20, seed: int = 0,
                        **options) -> dict:
    """``{name: sorted lifetimes}`` over ``episodes`` episodes of each simulator (``"gs"`` or
    a predictor spec), random policy."""
    hist = {}
    for name, sim in simulators.items():
        lives = []
        for ages in record_item_ages(env_id, agent, sim, episodes=episodes, seed=seed, **options):
            lives += item_lifetimes(ages)
        hist[name] = sorted(lives)
    return hist


def plot_lifetimes(hist: dict, path, lifetime: int | None = None, title: str = "") -> Path:
    """Histogram PNG (one panel per simulator, shares of items by lifetime)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt


    names = list(hist)
    top = max([max(v) for v in hist.values() if v] + [lifetime or 1]) + 1
    fig, axes = plt.subplots(1, len(names), figsize=(4 * len(names), 3.2), sharey=True, squeeze=False)
    for ax, name in zip(axes[0], names):
        v = np.asarray(hist[name], dtype=int)
        counts = np.bincount(v, minlength=top + 1)[1:top + 1] if v.size else np.zeros(top)
        share = counts / max(counts.sum(), 1)
        ax.bar(np.arange(1, top + 1), share, color="tab:orange" if name == "GS" else "tab:blue")
        if lifetime:
            ax.axvline(lifetime, color="k", ls="--", lw=0.8)
        ax.set_title(f"{name} ({v.size} items)")
        ax.set_xlabel("item lifetime (steps)")
    axes[0][0].set_ylabel("share of items")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return path


def run_lifetimes(params: dict, out_dir) -> dict:
    """The lifetimes job: histograms of the GS and each AIP in ``params["aips"]``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sims = {"GS": "gs", **params["aips"]}
    hist = lifetime_histograms(params["env_id"], params["agent"], sims, episodes=params["episodes"],
                               **params["options"])
    lifetime = params["options"].get("item_lifetime")
    plot_lifetimes(hist, out / "lifetimes.png", lifetime,
                   f"{params['env_id']} {params['agent']}: item lifetimes (item_lifetime={lifetime})")
    summary = {k: {"items": len(v), "mean": float(np.mean(v)) if v else None,
                   "share_at_lifetime": float(np.mean(np.asarray(v) == lifetime)) if v and lifetime else None}
               for k, v in hist.items()}
    data = {"env_id": params["env_id"], "agent": params["agent"], "options": params["options"],
            "episodes": params["episodes"], "policy": "uniform_random", "lifetimes": hist, "summary": summary}
    _write_json(out / "lifetimes.json", data)
    return data


# --------------------------------------------------------------------------------------------
# d-set ablation


def off_policy_cross_entropy(predictors: dict, on_policy, on_policy_episodes, off_policy: dict) -> dict:
    """Cross-entropy (nats) of each predictor on the on-policy test episodes and on each
    off-policy data set, and the increase off-policy (``off - on``).

    Returns ``{name: {"on_policy": ce, "off_policy": {data: ce}, "increase": {data: ce - on}}}``."""

    if not predictors:
        raise BadInput("predictors must not be empty")
    out = {}
    for name, pred in predictors.items():
        on = evaluate_cross_entropy(pred, on_policy, on_policy_episodes)
        off = {k: evaluate_cross_entropy(pred, ds) for k, ds in off_policy.items()}
        out[name] = {"on_policy": on, "off_policy": off, "increase": {k: v - on for k, v in off.items()}}
    return out


def biased_policy(env_id: str, seed: int = 0, p: float = 0.7):
    """A random policy that takes action 0 with probability ``p`` (traffic: keep the green,
    so the light switches rarely; warehouse: mostly up)."""

    n = get_domain(env_id).n_actions
    rng = np.random.default_rng(seed)

    def act(obs):
        return 0 if rng.random() < p else int(rng.integers(1, n))

    act.__name__ = f"biased_random_p{p}"
    return act


def _ablation_direction(train, test_sets: dict, arch: str, epochs, seed: int) -> dict:
    """AIPs on the d-set and the full observation (+ references) trained on ``train``, scored
    on its own test split and on each data set of ``test_sets``."""

    train_idx, test_idx = train.split(0.1, seed=seed)
    preds, reports = {}, {}
    for kind in ("dset", "full"):
        pred, rep = train_predictor(train, arch=arch, dset_kind=kind, epochs=epochs, seed=seed, progress=False,
                                    **_study_training(arch))
        preds[kind] = pred
        reports[kind] = {k: rep[k] for k in ("cross_entropy", "train_seconds", "hyperparameters")}
    preds["marginal"] = MarginalPredictor.fit(train, episodes=train_idx)
    preds["uniform"] = UniformPredictor(train.region, probs=untrained_probs(train.region))
    preds["untrained"] = untrained_predictor(train.region, arch=arch, seed=seed)
    return {"cross_entropy": off_policy_cross_entropy(preds, train, test_idx, test_sets), "training": reports}


def dset_ablation(params: dict, out_dir) -> dict:
    """The d-set ablation in both directions.

    Main direction (the paper's setting): AIPs on the d-set and on the full observation
    trained on uniform-random-policy data, tested on data from the scripted controller (the
    learner follows the domain's scripted/actuated controller) and from a biased random
    policy. Reverse direction (``"reverse"``): trained on the scripted controller's data --
    a policy whose actions depend on the local state, so the full observation (e.g. the light
    state in traffic) can carry correlations with the influence sources that do not hold
    under another policy -- and tested on the random and biased data."""

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    env_id, agent, seed = params["env_id"], params["agent"], int(params.get("seed", 0))
    arch = params.get("arch") or get_domain(env_id).default_predictor
    epochs = params.get("epochs")
    data = collect(env_id, agent, steps=params["steps"], seed=seed, progress=False)
    off = {
        "scripted": collect(env_id, agent, steps=params["offpolicy_steps"], seed=seed + 1,
                            gs_options={"scripted_learners": True}, progress=False),
        "biased": collect(env_id, agent, steps=params["offpolicy_steps"], seed=seed + 2,
                          policy=biased_policy(env_id, seed + 2), progress=False),
    }

    def describe(k, v):
        # with scripted_learners the learner's actions are ignored: the controller acts
        return {"steps": v.n_steps, "gs_options": v.metadata.get("gs_options"),
                "policy": "scripted controller" if k == "scripted" else v.metadata.get("policy")}

    main = _ablation_direction(data, off, arch, epochs, seed)
    reverse = _ablation_direction(off["scripted"], {"random": data, "biased": off["biased"]}, arch, epochs, seed)
    result = {"env_id": env_id, "agent": agent, "arch": arch, "train_steps": data.n_steps,
              "train_policy": data.metadata.get("policy"),
              "off_policy_data": {k: describe(k, v) for k, v in off.items()},
              "cross_entropy": main["cross_entropy"], "training": main["training"],
              "reverse": {"train_policy": "scripted controller", "train_steps": off["scripted"].n_steps,
                          "off_policy_data": {"random": describe("random", data),
                                              "biased": describe("biased", off["biased"])},
                          "cross_entropy": reverse["cross_entropy"], "training": reverse["training"]}}
    _write_json(out / "dset.json", result)
    return result
