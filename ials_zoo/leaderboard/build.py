"""Building results: from evaluations (one per training seed) to a result dict.

A result is the GS score of a policy on one of two tracks:

* ``single-agent``: one agent (``agent``) controlled by the policy, every other agent scripted;
* ``multi-agent``: every agent of the GS (``agents``) acting with its own policy; an episode's
  score is the mean over agents of each agent's return, and ``per_agent_scores`` keeps each
  agent's mean.

The score of one training seed is the mean over the evaluation episodes with a BCa bootstrap
interval over episodes; with several seeds the overall score is the mean of the seed means
with a Student-t interval over seeds (:mod:`ials_zoo.stats`).
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import platform
import re
from collections.abc import Sequence

import numpy as np

import ials_zoo
from ials_zoo import reference_speed
from ials_zoo.core.domains import get_domain
from ials_zoo.errors import BadInput
from ials_zoo.evaluation import PROTOCOL_EPISODES, REFERENCE_POLICIES, eval_seeds, evaluate, evaluate_joint, load_policy
from ials_zoo.stats import EPISODES_METHOD, SEEDS_METHOD, t_interval

SCHEMA_VERSION = 2
SINGLE, MULTI = "single-agent", "multi-agent"
OFFICIAL, VARIANT = "official", "variant"


def hardware_info() -> dict:
    """Where a result was measured (for the ``hardware`` field)."""
    processor = reference_speed.processor_name()
    versions = {}
    for name in ("torch", "numpy", "scipy"):
        try:
            versions[name] = __import__(name).__version__
        except ImportError:  # pragma: no cover - all are dependencies
            versions[name] = None
    return {
        "platform": platform.platform(),
        "processor": processor or "unknown",
        "cpu_count": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
        "python": platform.python_version(),
        **versions,
    }


def split_env_id(env_id: str) -> tuple[str, int]:
    """``"warehouse_v0"`` -> ``("warehouse", 0)``."""
    m = re.fullmatch(r"([a-z][a-z0-9_]*)_v([0-9]+)", env_id or "")
    if not m:
        raise BadInput(f"env_id {env_id!r} is not of the form '<domain>_v<version>'")
    return m.group(1), int(m.group(2))


def now_iso() -> str:
    return _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def overall_score(scores: Sequence[dict]) -> dict:
    """The ``score`` field from the per-seed scores: one seed's own interval over episodes, or
    the mean of the seed means with a t-interval over seeds."""
    if len(scores) == 1:
        s = scores[0]
        return {"mean": s["mean"], "ci_low": s["ci_low"], "ci_high": s["ci_high"], "ci_over": "episodes"}
    mean, lo, hi = t_interval([s["mean"] for s in scores])
    return {"mean": mean, "ci_low": lo, "ci_high": hi, "ci_over": "seeds"}


def overall_metrics(scores: Sequence[dict]) -> dict | None:
    """The physical metrics of a result: one seed's own (interval over episodes), or the mean
    over seeds with the Student-t interval (as :func:`overall_score`); None when the seeds
    carry no metrics (or not the same ones)."""
    per_seed = [s.get("metrics") for s in scores]
    if not per_seed or any(not m for m in per_seed) or len({tuple(sorted(m)) for m in per_seed}) != 1:
        return None
    if len(per_seed) == 1:
        return {k: dict(v) for k, v in per_seed[0].items()}
    out = {}
    for name in per_seed[0]:
        mean, lo, hi = t_interval([m[name]["mean"] for m in per_seed])
        out[name] = {"mean": mean, "ci_low": lo, "ci_high": hi}
    return out


def per_agent_scores(scores: Sequence[dict]) -> dict:
    """Each agent's mean return over seeds and episodes (multi-agent track)."""
    agents = list(scores[0]["per_agent_returns"])
    return {a: float(np.mean([np.mean(s["per_agent_returns"][a]) for s in scores])) for a in agents}


def protocol_of(track: str, env_id: str, agents, seeds, options) -> str:
    """``official`` when a result follows the benchmark's protocol -- the protocol's seeds and
    episode count, no GS options but the domain's track options (e.g. the network) and what its
    policy observes (:attr:`Domain.policy_options`), and on the multi-agent track every agent --
    else ``variant``."""
    domain = get_domain(env_id)
    # the track options are named, not left to their defaults (one track per network), and no other
    # option changes the episode or its score
    if list(seeds) != eval_seeds() or set(options) - set(domain.policy_options) != set(domain.track_options):
        return VARIANT
    tracked = {k: v for k, v in options.items() if k in domain.track_options}
    if track == MULTI and list(agents) != domain.agents(**tracked):
        return VARIANT
    return OFFICIAL


def make_result(evaluations: Sequence, *, algorithm: str, training: dict | None = None,
                training_seeds: Sequence[int | None] | None = None,
                learning_curves: Sequence[dict] = (), trained_agents: Sequence[str] | None = None,
                submitter: str = "", notes: str = "") -> dict:
    """Build a result dict from one :class:`~ials_zoo.evaluation.EvaluationResult` per
    training seed (all of one domain, agents and evaluation seeds). An evaluation of one agent
    (``ev.agent`` set) makes a single-agent result, a joint one (``ev.agent`` None) a
    multi-agent result."""
    if not evaluations:
        raise BadInput("make_result needs at least one evaluation")
    first = evaluations[0]
    for ev in evaluations[1:]:
        if (ev.env_id, ev.agent, list(ev.agents), ev.seeds, ev.options) != (
                first.env_id, first.agent, list(first.agents), first.seeds, first.options):
            raise BadInput("all evaluations of a result must share domain, agents, seeds and options")
    seeds = list(training_seeds) if training_seeds is not None else [None] * len(evaluations)
    if len(seeds) != len(evaluations):
        raise BadInput(f"{len(seeds)} training seeds for {len(evaluations)} evaluations")
    track = SINGLE if first.agent is not None else MULTI
    domain, version = split_env_id(first.env_id)
    scores = []
    for s, ev in zip(seeds, evaluations):
        entry = {"seed": s, "policy_file": ev.policy_file, "policy_sha256": ev.policy_sha256,
                 "mean": ev.mean, "ci_low": ev.ci_low, "ci_high": ev.ci_high, "returns": list(ev.returns)}
        if track == MULTI:
            entry["per_agent_returns"] = {a: list(v) for a, v in ev.per_agent_returns.items()}
        if ev.metrics:
            entry["metrics"] = {k: dict(v) for k, v in ev.metrics.items()}
        scores.append(entry)
    options = dict(first.options or {})
    evaluation = {
        "simulator": "gs", "neighbours": "scripted" if track == SINGLE else "learners",
        "episodes": len(first.seeds), "seeds": list(first.seeds), "ci_level": 0.95,
        "ci_method": {"episodes": EPISODES_METHOD, "seeds": SEEDS_METHOD},
        "deterministic": bool(first.deterministic), "options": options,
        "protocol": protocol_of(track, first.env_id, first.agents, first.seeds, options),
    }
    result = {
        "schema_version": SCHEMA_VERSION,
        "track": track,
        "env_id": first.env_id,
        "domain": domain,
        "domain_version": version,
        "agent": first.agent,
        "agents": list(first.agents),
        "trained_agents": list(trained_agents if trained_agents is not None
                               else (list(first.agents) if training else [])),
        "policy": {"name": first.policy, "kind": first.policy_kind,
                   "frame_stack": int(first.frame_stack), "deterministic": bool(first.deterministic)},
        "algorithm": algorithm,
        "training": training,
        "hardware": hardware_info(),
        "evaluation": evaluation,
        "scores": scores,
        "score": overall_score(scores),
        "learning_curves": list(learning_curves),
        "package_version": ials_zoo.__version__,
        "created": now_iso(),
        "submitter": submitter,
        "notes": notes,
    }
    if track == MULTI:
        result["per_agent_scores"] = per_agent_scores(scores)
    metrics = overall_metrics(scores)
    if metrics:
        result["metrics"] = metrics
    return result


def reference_result(env_id: str, agent: str | None, policy: str, episodes: int | None = None,
                     submitter: str = "", notes: str = "", **options) -> dict:
    """Evaluate a reference policy (``"random"`` or ``"scripted"``) and build its result:
    for one agent (``agent``), or for every agent at once (``agent=None``, multi-agent)."""
    if policy not in REFERENCE_POLICIES:
        raise BadInput(f"reference policy must be one of {REFERENCE_POLICIES}, got {policy!r}")
    episodes = PROTOCOL_EPISODES if episodes is None else episodes
    if agent is None:
        ev = evaluate_joint(env_id, policy, episodes=episodes, **options)
    else:
        ev = evaluate(env_id, agent, policy, episodes=episodes, **options)
    return make_result([ev], algorithm=policy, submitter=submitter, notes=notes)


def external_training(algorithm: str, env_steps: int, seconds: float = 0.0, seed: int = 0) -> dict:
    """The training claims of a policy our trainers did not make (SCHEMA.md's ``external``):
    what its submitter says, labelled on the board as unverified."""
    if not isinstance(algorithm, str) or not algorithm.strip():
        raise BadInput("--algorithm must name the algorithm that trained the policy")
    if isinstance(env_steps, bool) or not isinstance(env_steps, int) or env_steps < 0:
        raise BadInput(f"--env-steps must be a whole number >= 0, got {env_steps!r}")
    if not (math.isfinite(seconds) and seconds >= 0):
        raise BadInput(f"--training-seconds must be a finite number >= 0, got {seconds!r}")
    return {"algorithm": algorithm.strip(), "seed": int(seed),
            "training": {"simulator": "external", "aip": None, "seeds": [int(seed)], "env_steps": env_steps,
                         "wall_clock_seconds": float(seconds), "aip_seconds": 0.0, "hyperparameters": {}}}


def result_for(env_id, agent, policy, episodes, deterministic=False, frame_stack=None,
               submitter="", notes="", progress=False, options: dict | None = None, joint: bool = False,
               external: dict | None = None, need_record: bool = False) -> dict:
    """Evaluate ``policy`` and build its leaderboard result (training record from a model's
    metadata; none for reference policies and callables). A model without a training record
    takes ``external`` (:func:`external_training`); with ``need_record`` (the result is to be
    written) and neither, a :class:`BadInput` before any episode."""
    pol = load_policy(policy, env_id, agent, deterministic=deterministic, frame_stack=frame_stack)
    meta = pol.metadata if pol.kind == "model" else {}
    if pol.kind == "model" and meta.get("training") and external is not None:
        raise BadInput("the policy file carries its trainer's record; --algorithm/--env-steps are for policies "
                       "trained elsewhere")
    if pol.kind == "model" and not meta.get("training"):
        if external is None and need_record:
            raise BadInput(f"{policy!r} carries no training record (not trained by ials_zoo's baselines): give "
                           "--algorithm and --env-steps (and --training-seconds, --training-seed) to write a result; "
                           "it is labelled external, its training claims unverified")
        meta = dict(meta, **(external or {}))
    env_id = env_id or meta.get("env_id")
    if env_id is None:
        raise BadInput("--env is required unless the policy is a model that names its domain")
    domain = get_domain(env_id)
    if pol.kind == "model" and len(pol.agents) > 1 and agent is None:
        joint = True
    options = meta.get("env_options", {}) if options is None else options
    if joint:
        if agent is not None:
            raise BadInput("--joint scores every agent: leave out --agent")
        ev = evaluate_joint(env_id, pol, episodes=episodes, deterministic=deterministic, progress=progress, **options)
    else:
        agent = agent or (pol.agents[0] if pol.kind == "model" else domain.default_agents[0])
        ev = evaluate(env_id, agent, pol, episodes=episodes, deterministic=deterministic,
                      frame_stack=frame_stack, progress=progress, **options)
    if meta.get("training"):
        seed = meta.get("seed")
        curve = meta.get("learning_curve") or []
        return make_result([ev], algorithm=meta.get("algorithm", "model"), training=meta["training"],
                           training_seeds=[seed],
                           learning_curves=[{"seed": seed, "points": curve}] if curve else [],
                           trained_agents=list(pol.agents), submitter=submitter, notes=notes)
    algorithm = ev.policy_kind if ev.policy_kind in ("random", "scripted", "callable") else "model"
    if ev.policy_kind == "rule":
        algorithm = ev.policy  # a rule's entry is named as itself
    return make_result([ev], algorithm=algorithm, submitter=submitter, notes=notes)


__all__ = [
    "MULTI",
    "OFFICIAL",
    "SCHEMA_VERSION",
    "SINGLE",
    "VARIANT",
    "external_training",
    "hardware_info",
    "make_result",
    "now_iso",
    "overall_score",
    "protocol_of",
    "reference_result",
    "result_for",
    "split_env_id",
]
