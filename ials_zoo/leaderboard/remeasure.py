"""Scoring an entry's policies again with the entry's own protocol, episode by episode (what
``submit`` and ``verify`` both rely on): evaluation is deterministic, so a return that differs
by more than float noise (relative 1e-9) is a different return."""

from __future__ import annotations

import math

from ials_zoo.evaluation import estimate_evaluation_seconds, evaluate, evaluate_joint
from ials_zoo.leaderboard.build import MULTI
from ials_zoo.leaderboard.validate import REL_TOL, ResultError
from ials_zoo.utils import format_seconds

MAX_REMEASURE_SECONDS = 4 * 3600.0
"""What a re-measure may cost (estimated before it starts) unless the caller allows more."""


def _equal(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=REL_TOL, abs_tol=1e-12)


def check_remeasure_cost(data: dict, max_seconds: float = MAX_REMEASURE_SECONDS) -> float:
    """The estimated seconds of re-measuring every seed of ``data``
    (:func:`~ials_zoo.evaluation.estimate_evaluation_seconds`); a :class:`ResultError` naming
    the estimate when it is over ``max_seconds`` (a valid but huge ``max_cycles``, say)."""
    ev = data["evaluation"]
    seconds = len(data["scores"]) * estimate_evaluation_seconds(data["env_id"], ev["episodes"], **ev["options"])
    if seconds > max_seconds:
        raise ResultError("evaluation.options", f"re-measuring {len(data['scores'])} seed(s) x {ev['episodes']} "
                          f"episodes with options {ev['options']} would take about {format_seconds(seconds)} on 2 "
                          f"cores, over the limit of {format_seconds(max_seconds)}; refused before it starts "
                          "(--max-remeasure-hours allows more)")
    return seconds


def remeasure_result(data: dict, files: list[str] | None, progress: bool = False,
                     max_seconds: float = MAX_REMEASURE_SECONDS) -> list[dict]:
    """Evaluate every seed's policy (``files``, or the reference policy) again with the entry's
    protocol; one report per seed (see :func:`verify`). Refused before any episode when its
    estimated cost is over ``max_seconds`` (:func:`check_remeasure_cost`)."""
    check_remeasure_cost(data, max_seconds)
    kind = data["policy"]["kind"]
    ev = data["evaluation"]
    reports = []
    for i, s in enumerate(data["scores"]):
        spec = kind if kind in ("random", "scripted") else f"rule:{data['policy']['name']}" if kind == "rule" \
            else files[i]
        if data["track"] == MULTI:
            res = evaluate_joint(data["env_id"], spec, agents=data["agents"], seeds=ev["seeds"],
                                 deterministic=ev["deterministic"], progress=progress, **ev["options"])
        else:
            res = evaluate(data["env_id"], data["agent"], spec, seeds=ev["seeds"], deterministic=ev["deterministic"],
                           progress=progress, **ev["options"])
        diffs = [e for e, (a, b) in enumerate(zip(s["returns"], res.returns)) if not _equal(a, b)]
        if data["track"] == MULTI:
            for a in data["agents"]:
                diffs += [f"{a}:{e}" for e, (x, y) in enumerate(zip(s["per_agent_returns"][a], res.per_agent_returns[a]))
                          if not _equal(x, y)]
        metrics = {}
        for name, claimed in (s.get("metrics") or {}).items():
            measured = (res.metrics or {}).get(name)
            same_episodes = "episodes" not in claimed or (measured is not None and len(claimed["episodes"]) == len(
                measured.get("episodes", ())) and all(map(_equal, claimed["episodes"], measured["episodes"])))
            if measured is None or not same_episodes or not all(
                    _equal(claimed[k], measured[k]) for k in ("mean", "ci_low", "ci_high")):
                diffs.append(f"metrics.{name}")
                metrics[name] = (claimed["mean"], None if measured is None else measured["mean"])
        ok = not diffs and _equal(s["mean"], res.mean)
        reports.append({"seed": s["seed"], "claimed": s["mean"], "measured": res.mean,
                        "ci": [res.ci_low, res.ci_high], "ok": bool(ok), "differences": diffs,
                        "metric_differences": metrics})
    return reports


def mismatch_text(report: dict) -> str:
    """What a failed re-measure found, in words: the returns that differ (with full
    precision), or, when every return re-measures exactly, the metrics that do not."""
    seed = "-" if report["seed"] is None else report["seed"]
    returns = [d for d in report["differences"] if not str(d).startswith("metrics.")]
    if returns or not _equal(report["claimed"], report["measured"]):
        return (f"seed {seed} scores {report['measured']!r}, not the claimed {report['claimed']!r} (episodes "
                f"{returns[:5]} differ)")
    parts = [f"{name} claimed {claimed!r}, measured {'nothing' if measured is None else repr(measured)}"
             for name, (claimed, measured) in report["metric_differences"].items()]
    return f"seed {seed}'s returns re-measure exactly, but not its metrics: {'; '.join(parts)}"


__all__ = ["MAX_REMEASURE_SECONDS", "check_remeasure_cost", "mismatch_text", "remeasure_result"]
