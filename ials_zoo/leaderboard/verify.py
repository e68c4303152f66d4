"""Re-scoring an entry: the policy of every training seed is evaluated again on the GS with the
entry's own protocol, and the check passes only when every episode's return is re-measured
exactly (relative tolerance 1e-9: evaluation is deterministic, so anything more is not float
noise). Nothing named in a result is imported or run: policies are read as weights plus JSON
(a ``callable`` result is refused), and a model file must have its recorded sha256."""

from __future__ import annotations

from pathlib import Path

from ials_zoo.errors import BadInput
from ials_zoo.evaluation import load_model, sha256_file
from ials_zoo.leaderboard.remeasure import MAX_REMEASURE_SECONDS, check_remeasure_cost, remeasure_result
from ials_zoo.leaderboard.store import board_path, resolve_policy_file, training_provenance
from ials_zoo.leaderboard.validate import ResultError, load_result


def verify(path, policies=None, progress: bool = False, directory=None,
           max_seconds: float = MAX_REMEASURE_SECONDS) -> list[dict]:
    """Re-score the result at ``path``; one report per training seed: ``seed``, ``claimed``,
    ``measured``, ``ok`` (every episode equal, every physical metric equal), ``differences``
    (what differs). The training record in each policy file must agree with the result's
    (:func:`~ials_zoo.leaderboard.store.training_provenance`).

    ``policies``: the policy file of each seed, when the recorded ones are not found (next to
    the result, as given, or in the board)."""
    path = Path(path)
    data = load_result(path)
    kind = data["policy"]["kind"]
    if kind == "callable":
        raise ResultError("policy.kind", "a callable policy is code; verify never imports or runs it")
    check_remeasure_cost(data, max_seconds)
    if policies is not None and len(policies) != len(data["scores"]):
        raise BadInput(f"{len(policies)} policy files given for {len(data['scores'])} per-seed scores")
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
                raise BadInput(f"scores.{i}: policy file {given!r} not found; pass it with --policy")
            digest = sha256_file(found)
            if digest != s["policy_sha256"]:
                raise BadInput(f"scores.{i}.policy_sha256: {str(found)!r} has sha256 {digest}, the result "
                                 f"claims {s['policy_sha256']}")
            files.append(str(found))
        provenance = training_provenance(data, [load_model(f, data["agent"]).net for f in files])
        if data.get("provenance", provenance) != provenance:
            raise ResultError("provenance", f"the entry says {data['provenance']!r}, its policy files say {provenance!r}")
    return remeasure_result(data, files, progress, max_seconds)


__all__ = ["verify"]
