"""What a single-agent training run says about its simulator's AIP: the ``training.aip``
record of the result (its file, sha256 and cost). The ``--simulator`` vocabulary itself is
:mod:`ials_zoo.influence.specs`'s.
"""

from __future__ import annotations

import json
from pathlib import Path

from ials_zoo.evaluation import sha256_file
from ials_zoo.influence.specs import PredictorSpec

PACKAGE = Path(__file__).resolve().parents[1]  # the installed ials_zoo folder


def predictor_record(venv, spec: PredictorSpec | None) -> dict | None:
    """What the training record says about the AIP behind an IALS vec env (None on the GS:
    ``spec`` None; else the parsed ``--simulator``, :func:`ials_zoo.influence.specs.parse_simulator`).

    The IALS vec env exposes its predictor as ``venv.predictor``; a trained AIP's
    ``metadata`` holds its training report, with ``dataset.collect_seconds`` (Algorithm 1)
    and ``train_seconds``: their sum is added to the training wall-clock (as in the paper's
    plots) when this run made the AIP (``charged`` in the record), and only recorded when it
    was shipped or cached (the predictor's ``source``). An AIP file given by path is charged
    (the study trains one per run, and the paper's IALS cost includes it). Predictors that need
    neither (untrained, fixed) count 0; so does ``marginal``, whose metadata does not carry the
    data collection time (documented limitation). A shipped file is named relative to the
    package, not by an absolute path of this machine."""
    if spec is None:
        return None
    pred = getattr(venv, "predictor", None)
    meta = dict(getattr(pred, "metadata", None) or {})
    collect = (meta.get("dataset") or {}).get("collect_seconds") or meta.get("collect_seconds")
    train = meta.get("train_seconds")
    made_now, file = True, None
    if spec.kind == "file":
        file = spec.path
    elif spec.kind == "trained" and getattr(pred, "source", None) is not None:
        made_now = False
        file = pred.source if _in_package(pred.source) else None  # a cache path is this machine's alone
    sha = sha256_file(file) if file else None
    meta.pop("marginal", None)
    return {
        "variant": str(meta.get("variant") or spec),
        "class": type(pred).__name__ if pred is not None else None,
        "file": portable_path(file) if file else None,
        "charged": bool(made_now),
        "sha256": sha,
        "collection_seconds": float(collect or 0.0),
        "training_seconds": float(train or 0.0),
        "metadata": _jsonable(meta),
    }


def _in_package(path) -> bool:
    return Path(path).resolve().is_relative_to(PACKAGE)


def portable_path(path) -> str:
    """A file inside the installed package as ``ials_zoo/<path in the package>``; any other
    file as given."""
    try:
        return "ials_zoo/" + Path(path).resolve().relative_to(PACKAGE).as_posix()
    except ValueError:
        return str(path)


def _jsonable(obj):
    try:
        return json.loads(json.dumps(obj, default=str))
    except (TypeError, ValueError):
        return str(obj)
