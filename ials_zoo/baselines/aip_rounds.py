"""DIALS's AIP rounds: how often they come (``--refresh``), how they collect and train
(``--aip-training``, :class:`AIPTraining`), the AIPs a run starts from (``--aip``), and the
mixin that runs the rounds inside a learner (:class:`AIPRefreshes`). Shared by DIALS on array
IALS shards (:mod:`ials_zoo.baselines.dials`) and on a multi-agent IALS ParallelEnv
(:mod:`ials_zoo.baselines.dials_copies`), and read by the re-train's cost estimate."""

from __future__ import annotations

import time
from dataclasses import dataclass

from ials_zoo.baselines.aip_record import portable_path
from ials_zoo.baselines.multiagent import JointActor
from ials_zoo.core.extras import dials_of
from ials_zoo.errors import BadInput
from ials_zoo.evaluation import sha256_file
from ials_zoo.influence.dataset import collect_all
from ials_zoo.influence.fidelity import on_policy_training
from ials_zoo.influence.files import load_predictor_set
from ials_zoo.influence.multi import resolve_predictor_set, shipped_set_path
from ials_zoo.influence.networks import ARCHS
from ials_zoo.influence.train import train_predictors


def parse_refresh(text: str, default: int) -> int | None:
    """Steps per agent between AIP refreshes; 0: once, at the start; None: never."""
    t = str(text).strip().lower()
    if t == "default":
        return default
    if t == "once":
        return 0
    if t == "never":
        return None
    try:
        n = int(t.replace("_", ""))
    except ValueError:
        n = 0
    if n < 1:
        raise BadInput(f"--refresh {text!r}: expected a number of steps >= 1, 'once', 'never' or 'default'")
    return n


def autoregressive_of(args, domain) -> bool:
    """Whether the AIPs DIALS trains read ``u_{t-1}``: ``--aip-autoregressive``, else the domain's
    (always with ``--aip-training fidelity``)."""
    if args.aip_training == "fidelity":
        return True
    return bool(dials_of(domain).aip_autoregressive if args.aip_autoregressive is None else args.aip_autoregressive)


@dataclass(frozen=True)
class AIPTraining:
    """How DIALS collects and trains its AIPs at every refresh (:func:`aip_training_of`)."""

    collect_steps: int
    autoregressive: bool
    lr: float
    epochs: int
    lr_schedule: str
    influence_lags: int  # 0: memoryless
    clock_horizon: int  # 0: no clock


def aip_training_of(args, domain) -> AIPTraining:
    """``--aip-training`` resolved against the domain's :class:`~ials_zoo.core.extras.DIALSSettings`,
    with ``--collect-steps``, ``--aip-epochs`` and ``--aip-lr`` where given."""
    d = dials_of(domain)
    autoregressive = autoregressive_of(args, domain)
    if args.aip_training == "fidelity":
        lr, epochs, schedule, lags = on_policy_training(domain.env_id, True, args.aip_lr, args.aip_epochs)
        return AIPTraining(int(args.collect_steps or d.fidelity_collect_steps or d.collect_steps), True, lr, epochs,
                           schedule, lags, d.fidelity_aip_clock_horizon)
    return AIPTraining(int(args.collect_steps or d.collect_steps), autoregressive,
                       float(args.aip_lr or d.lr_for(autoregressive)), int(args.aip_epochs or d.aip_epochs),
                       d.aip_lr_schedule, 1 if autoregressive else 0, d.aip_clock_horizon)


def initial_aips(args, env_id, agents, options, seed) -> tuple[dict, float]:
    """``({agent: AIP}, seconds to charge)`` before round 0's collection (if any). Only AIPs
    this run trains are charged: a shipped set's recorded cost is reported in
    ``training.aip``, not added to this run's wall-clock."""

    if args.aip in ("trained", "untrained"):  # "trained": replaced by round 0's AIPs
        preds = resolve_predictor_set("untrained", env_id, agents, seed=seed, options=options)
        return dict(zip(agents, preds)), 0.0
    source = str(shipped_set_path(env_id)) if args.aip == "shipped" else args.aip
    preds = resolve_predictor_set(source, env_id, agents, seed=seed, options=options)
    return dict(zip(agents, preds)), 0.0


def refresh_aips(env_id, agents, options, net, seed, domain, training: AIPTraining, old, progress,
                 collect_workers=1):
    """Collect every region's data with the joint policy ``net`` (None: uniform random) and
    retrain every AIP as ``training`` says (warm start from ``old`` when it holds networks of
    the same shape and inputs)."""

    d = dials_of(domain)
    policy = None if net is None else JointActor(net, seed)
    t0 = time.perf_counter()
    data = collect_all(env_id, agents, steps=training.collect_steps, policy=policy, seed=seed, gs_options=options,
                       progress=progress, workers=collect_workers)
    collect_seconds = time.perf_counter() - t0
    lags, clock = training.influence_lags, training.clock_horizon
    warm = {a: p for a, p in old.items() if isinstance(p, ARCHS[d.aip_arch]) and p.hidden == d.aip_hidden
            and p.autoregressive == training.autoregressive and p.influence_lags == lags
            and p.clock_horizon == clock and p.metadata.get("variant") == "trained"}
    t0 = time.perf_counter()
    preds, report = train_predictors(data, d.aip_arch, hidden=d.aip_hidden, lr=training.lr, epochs=training.epochs,
                                     batch_size=d.aip_batch, seed=seed, init=warm or None, progress=progress,
                                     autoregressive=training.autoregressive, lr_schedule=training.lr_schedule,
                                     influence_lags=lags, clock_horizon=clock)
    train_seconds = time.perf_counter() - t0
    return preds, {"collect_seconds": collect_seconds, "train_seconds": train_seconds,
                   "mean_test_cross_entropy": report["mean_test_cross_entropy"], "warm_start": bool(warm)}


class AIPRefreshes:
    """The AIP rounds of a DIALS learner: at the refresh points, GS data from the joint policy and
    every AIP retrained (:func:`refresh_aips`), then :meth:`use_aips` hands them to the
    simulators. The learner has ``args``, ``domain``, ``agents``, ``options``, ``refresh``,
    ``aip_training``, ``aips``, ``refreshes``, ``charged_seconds``, ``aip_split`` and ``training``."""

    def use_aips(self, aips: dict) -> None:
        raise NotImplementedError

    def load_aips(self, state, info) -> None:
        """The run's first AIPs (``state`` None), or those of its checkpoint (``out/aips.pt``)."""
        args = self.args
        if state is None:
            self.aips, self.charged_seconds = initial_aips(args, args.env_id, self.agents, self.options, args.seed)
            if args.aip != "trained":
                self.training["aip"] = fixed_aip_record(args.aip, args.env_id, self.aips)
            return
        self.aips = load_predictor_set(self.out / "aips.pt", env_id=args.env_id)
        self.charged_seconds, self.refreshes = float(info["aip_seconds"]), int(info["refreshes"])
        self.aip_split = info.get("aip_split", self.aip_split)
        self.training["aip"] = info.get("aip")

    def aip_info(self) -> dict:
        """What :meth:`load_aips` reads back from a checkpoint's info."""
        return {"aip_seconds": self.charged_seconds, "refreshes": self.refreshes, "aip_split": self.aip_split,
                "aip": self.training["aip"]}

    def _next_refresh(self):
        """Steps per agent at which the AIPs are next retrained (None: never again)."""
        if self.args.aip != "trained" or self.refresh is None:
            return None
        if self.refreshes == 0:
            return 0
        return self.refreshes * self.refresh if self.refresh > 0 else None

    def next_stop(self, steps):
        due = self._next_refresh()
        return due if due is not None and due > steps else None

    def before_training(self, steps, total, policy, note):
        due = self._next_refresh()
        if due is None or due > steps:
            return
        args, d, n, how = self.args, dials_of(self.domain), self.refreshes, self.aip_training
        net = policy() if steps > 0 else None
        note(f"AIP round {n}: GS collection + training")
        clock = f"clock {how.clock_horizon}" if how.clock_horizon else ""
        kind = (f"autoregressive (last {how.influence_lags} draw{'s' if how.influence_lags > 1 else ''}"
                f"{', ' + clock if clock else ''}) " if how.autoregressive else f"({clock}) " if clock else "")
        print(f"dials: AIP round {n} at {steps:,} steps per agent: {how.collect_steps:,} GS steps of "
              f"{'the joint policy' if net else 'uniformly random agents'}, then {len(self.agents)} "
              f"{kind}{d.aip_arch.upper()} AIPs x {how.epochs} epochs ...", flush=True)
        self.aips, rep = refresh_aips(args.env_id, self.agents, self.options, net, args.seed + n, self.domain, how,
                                      self.aips, progress=False)
        print(f"dials: AIP round {n} done: collection {rep['collect_seconds']:.0f} s, training "
              f"{rep['train_seconds']:.0f} s, mean test cross-entropy {rep['mean_test_cross_entropy']:.3f}", flush=True)
        self.charged_seconds += rep["collect_seconds"] + rep["train_seconds"]
        self.aip_split["collect"] += rep["collect_seconds"]
        self.aip_split["train"] += rep["train_seconds"]
        self.use_aips(self.aips)
        self.refreshes += 1
        self.training["aip"] = {"variant": "trained", "file": None, "sha256": None,
                                "collection_seconds": self.aip_split["collect"],
                                "training_seconds": self.aip_split["train"], "refreshes": self.refreshes,
                                "last": dict(rep, at_steps_per_agent=steps)}


def fixed_aip_record(aip: str, env_id: str, aips: dict) -> dict:
    """``training.aip`` of AIPs that DIALS does not train (untrained, fixed, shipped, a file):
    a file's recorded collection and training seconds, not charged to this run."""

    path = shipped_set_path(env_id) if aip == "shipped" else (aip if aip.endswith(".pt") else None)
    first = next(iter(aips.values()))
    collect = max(float(p.metadata.get("dataset", {}).get("collect_seconds") or 0.0) for p in aips.values())
    train = max(float(p.metadata.get("train_seconds") or 0.0) for p in aips.values())
    return {"variant": first.metadata.get("variant", aip) if path else aip,
            "file": None if path is None else portable_path(path),
            "sha256": None if path is None else sha256_file(path), "charged": False,
            "collection_seconds": collect if path else 0.0, "training_seconds": train if path else 0.0,
            "refreshes": 0}


