"""Merging the single-seed results of one experiment into one result (score and CI over seeds)."""

from __future__ import annotations

from collections.abc import Sequence

from ials_zoo import reference_speed
from ials_zoo.errors import BadInput
from ials_zoo.leaderboard.build import MULTI, now_iso, overall_metrics, overall_score, per_agent_scores
from ials_zoo.leaderboard.validate import ResultError, validate_result


def merge_results(results: Sequence[dict], submitter: str | None = None, notes: str | None = None) -> dict:
    """Combine single-seed results of the same experiment (same track, domain, agents,
    algorithm, training simulator and evaluation; different training seeds) into one result
    with a score per seed and the overall score over seeds.

    ``training.env_steps`` must agree; ``wall_clock_seconds`` and ``aip_seconds`` become the
    means over seeds, and ``reference`` the seeds' together (:func:`ials_zoo.reference_speed.merged`;
    documented in SCHEMA.md)."""
    if len(results) < 2:
        raise BadInput("merge needs at least two results")
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
    training.pop("reference", None)
    reference = reference_speed.merged([r["training"].get("reference") for r in results])
    if reference is not None:
        training["reference"] = reference
    merged = dict(first, training=training, scores=scores, score=overall_score(scores),
                  learning_curves=[c for r in results for c in r["learning_curves"]],
                  created=now_iso(),
                  submitter=first["submitter"] if submitter is None else submitter,
                  notes=first["notes"] if notes is None else notes)
    if first["track"] == MULTI:
        merged["per_agent_scores"] = per_agent_scores(scores)
    merged.pop("metrics", None)
    metrics = overall_metrics(scores)
    if metrics:
        merged["metrics"] = metrics
    return validate_result(merged)


__all__ = ["merge_results"]
