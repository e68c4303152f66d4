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
import os
import platform
import re
from collections.abc import Sequence

import numpy as np

from ials_zoo.stats import EPISODES_METHOD, SEEDS_METHOD, t_interval

SCHEMA_VERSION = 2
SINGLE, MULTI = "single-agent", "multi-agent"
OFFICIAL, VARIANT = "official", "variant"


def hardware_info() -> dict:
    """Where a result was measured (for the ``hardware`` field)."""
    processor = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    processor = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
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
        raise ValueError(f"env_id {env_id!r} is not of the form '<domain>_v<version>'")
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


def per_agent_scores(scores: Sequence[dict]) -> dict:
    """Each agent's mean return over seeds and episodes (multi-agent track)."""
    agents = list(scores[0]["per_agent_returns"])
    return {a: float(np.mean([np.mean(s["per_agent_returns"][a]) for s in scores])) for a in agents}


def protocol_of(track: str, env_id: str, agents, seeds, options) -> str:
    """``official`` when a result follows the benchmark's protocol -- the protocol's seeds and
    episode count, no GS options, and on the multi-agent track every agent -- else ``variant``."""
    from ials_zoo.core.domains import get_domain
    from ials_zoo.evaluation import eval_seeds

    if list(seeds) != eval_seeds() or options:
        return VARIANT
    if track == MULTI and list(agents) != get_domain(env_id).agents():
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
    import ials_zoo

    if not evaluations:
        raise ValueError("make_result needs at least one evaluation")
    first = evaluations[0]
    for ev in evaluations[1:]:
        if (ev.env_id, ev.agent, list(ev.agents), ev.seeds, ev.options) != (
                first.env_id, first.agent, list(first.agents), first.seeds, first.options):
            raise ValueError("all evaluations of a result must share domain, agents, seeds and options")
    seeds = list(training_seeds) if training_seeds is not None else [None] * len(evaluations)
    if len(seeds) != len(evaluations):
        raise ValueError(f"{len(seeds)} training seeds for {len(evaluations)} evaluations")
    track = SINGLE if first.agent is not None else MULTI
    domain, version = split_env_id(first.env_id)
    scores = []
    for s, ev in zip(seeds, evaluations):
        entry = {"seed": s, "policy_file": ev.policy_file, "policy_sha256": ev.policy_sha256,
                 "mean": ev.mean, "ci_low": ev.ci_low, "ci_high": ev.ci_high, "returns": list(ev.returns)}
        if track == MULTI:
            entry["per_agent_returns"] = {a: list(v) for a, v in ev.per_agent_returns.items()}
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
    return result


def reference_result(env_id: str, agent: str | None, policy: str, episodes: int | None = None,
                     submitter: str = "", notes: str = "", **options) -> dict:
    """Evaluate a reference policy (``"random"`` or ``"scripted"``) and build its result:
    for one agent (``agent``), or for every agent at once (``agent=None``, multi-agent)."""
    from ials_zoo.evaluation import PROTOCOL_EPISODES, REFERENCE_POLICIES, evaluate, evaluate_joint

    if policy not in REFERENCE_POLICIES:
        raise ValueError(f"reference policy must be one of {REFERENCE_POLICIES}, got {policy!r}")
    episodes = PROTOCOL_EPISODES if episodes is None else episodes
    if agent is None:
        ev = evaluate_joint(env_id, policy, episodes=episodes, **options)
    else:
        ev = evaluate(env_id, agent, policy, episodes=episodes, **options)
    return make_result([ev], algorithm=policy, submitter=submitter, notes=notes)


def merge_results(results: Sequence[dict], submitter: str | None = None, notes: str | None = None) -> dict:
    """Combine single-seed results of the same experiment (same track, domain, agents,
    algorithm, training simulator and evaluation; different training seeds) into one result
    with a score per seed and the overall score over seeds.

    ``training.env_steps`` must agree; ``wall_clock_seconds`` and ``aip_seconds`` become the
    means over seeds (documented in SCHEMA.md)."""
    from ials_zoo.leaderboard.validate import ResultError, validate_result

    if len(results) < 2:
        raise ValueError("merge needs at least two results")
    for i, r in enumerate(results):
        try:
            validate_result(r)
        except ResultError as exc:
            raise ResultError(f"results[{i}].{exc.field}", str(exc)) from None
        if r["training"] is None:
            raise ResultError(f"results[{i}].training", "only trained policies have seeds to merge")
    first = results[0]

    def same(key_fn, field):
        for i, r in enumerate(results[1:], 1):
            if key_fn(r) != key_fn(first):
                raise ResultError(f"results[{i}].{field}", f"differs from results[0]: "
                                  f"{key_fn(r)!r} vs {key_fn(first)!r}")

    for field in ("track", "env_id", "agent", "agents", "algorithm", "evaluation"):
        same(lambda r, f=field: r[f], field)
    same(lambda r: r["policy"]["kind"], "policy.kind")
    same(lambda r: r["policy"]["frame_stack"], "policy.frame_stack")
    same(lambda r: r["training"]["simulator"], "training.simulator")
    same(lambda r: r["training"]["env_steps"], "training.env_steps")
    scores = [s for r in results for s in r["scores"]]
    seeds = [s["seed"] for s in scores]
    if len(set(seeds)) != len(seeds):
        raise ResultError("scores", f"training seeds repeat: {seeds}")
    n = len(results)
    training = dict(first["training"], seeds=seeds,
                    wall_clock_seconds=sum(r["training"]["wall_clock_seconds"] for r in results) / n,
                    aip_seconds=sum(r["training"]["aip_seconds"] for r in results) / n)
    merged = dict(first, training=training, scores=scores, score=overall_score(scores),
                  learning_curves=[c for r in results for c in r["learning_curves"]],
                  created=now_iso(),
                  submitter=first["submitter"] if submitter is None else submitter,
                  notes=first["notes"] if notes is None else notes)
    if first["track"] == MULTI:
        merged["per_agent_scores"] = per_agent_scores(scores)
    return validate_result(merged)


__all__ = [
    "MULTI",
    "OFFICIAL",
    "SCHEMA_VERSION",
    "SINGLE",
    "VARIANT",
    "hardware_info",
    "make_result",
    "merge_results",
    "now_iso",
    "overall_score",
    "protocol_of",
    "reference_result",
    "split_env_id",
]
