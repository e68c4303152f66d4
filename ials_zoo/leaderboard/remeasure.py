"""Scoring an entry's policies again with the entry's own protocol, episode by episode (what
``submit`` and ``verify`` both rely on): evaluation is deterministic, so a return that differs
by more than float noise (relative 1e-9) is a different return."""

from __future__ import annotations

import math

from ials_zoo.evaluation import evaluate, evaluate_joint
from ials_zoo.leaderboard.build import MULTI
from ials_zoo.leaderboard.validate import REL_TOL


def _equal(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=REL_TOL, abs_tol=1e-12)


def remeasure_result(data: dict, files: list[str] | None, progress: bool = False) -> list[dict]:
    """Evaluate every seed's policy (``files``, or the reference policy) again with the entry's
    protocol; one report per seed (see :func:`verify`)."""
    kind = data["policy"]["kind"]
    ev = data["evaluation"]
    reports = []
    for i, s in enumerate(data["scores"]):
        spec = kind if kind in ("random", "scripted") else files[i]
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
        for name, claimed in (s.get("metrics") or {}).items():
            measured = (res.metrics or {}).get(name)
            if measured is None or not all(_equal(claimed[k], measured[k]) for k in ("mean", "ci_low", "ci_high")):
                diffs.append(f"metrics.{name}")
        ok = not diffs and _equal(s["mean"], res.mean)
        reports.append({"seed": s["seed"], "claimed": s["mean"], "measured": res.mean,
                        "ci": [res.ci_low, res.ci_high], "ok": bool(ok), "differences": diffs})
    return reports


__all__ = ["remeasure_result"]
