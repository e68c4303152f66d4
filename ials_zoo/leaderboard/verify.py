"""Re-scoring an entry: the policy of every training seed is evaluated again on the GS with the
entry's own protocol, and the check passes only when every episode's return is re-measured
exactly (relative tolerance 1e-9: evaluation is deterministic, so anything more is not float
noise). Nothing named in a result is imported or run: policies are read as weights plus JSON
(a ``callable`` result is refused), and a model file must have its recorded sha256."""

from __future__ import annotations

import math
from pathlib import Path

from ials_zoo.leaderboard.build import MULTI
from ials_zoo.leaderboard.store import board_path, resolve_policy_file
from ials_zoo.leaderboard.validate import REL_TOL, ResultError, load_result


def _equal(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=REL_TOL, abs_tol=1e-12)


def verify(path, policies=None, progress: bool = False, directory=None) -> list[dict]:
    """Re-score the result at ``path``; one report per training seed: ``seed``, ``claimed``,
    ``measured``, ``ok`` (every episode equal, every physical metric equal), ``differences``
    (what differs). The training record in each policy file must agree with the result's
    (:func:`~ials_zoo.leaderboard.store.training_provenance`).

    ``policies``: the policy file of each seed, when the recorded ones are not found (next to
    the result, as given, or in the board)."""
    from ials_zoo.evaluation import load_model, sha256_file
    from ials_zoo.leaderboard.store import training_provenance

    path = Path(path)
    data = load_result(path)
    kind = data["policy"]["kind"]
    if kind == "callable":
        raise ResultError("policy.kind", "a callable policy is code; verify never imports or runs it")
    if policies is not None and len(policies) != len(data["scores"]):
        raise ValueError(f"{len(policies)} policy files given for {len(data['scores'])} per-seed scores")
    try:
        board = board_path(directory)
    except ValueError:
        board = None
    files = None
    if kind == "model":
        files = []
        for i, s in enumerate(data["scores"]):
            given = policies[i] if policies else s["policy_file"]
            found = resolve_policy_file(given, path, board)
            if found is None:
                raise ValueError(f"scores.{i}: policy file {given!r} not found; pass it with --policy")
            digest = sha256_file(found)
            if digest != s["policy_sha256"]:
                raise ValueError(f"scores.{i}.policy_sha256: {str(found)!r} has sha256 {digest}, the result "
                                 f"claims {s['policy_sha256']}")
            files.append(str(found))
        provenance = training_provenance(data, [load_model(f, data["agent"]).net for f in files])
        if data.get("provenance", provenance) != provenance:
            raise ResultError("provenance", f"the entry says {data['provenance']!r}, its policy files say {provenance!r}")
    return remeasure_result(data, files, progress)


def remeasure_result(data: dict, files: list[str] | None, progress: bool = False) -> list[dict]:
    """Evaluate every seed's policy (``files``, or the reference policy) again with the entry's
    protocol; one report per seed (see :func:`verify`)."""
    from ials_zoo.evaluation import evaluate, evaluate_joint

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


__all__ = ["remeasure_result", "verify"]
