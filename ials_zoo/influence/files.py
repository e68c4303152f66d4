"""Influence-predictor files: weights plus plain JSON, loaded without unpickling.

One ``torch.save`` of a plain dict, read back with ``torch.load(weights_only=True)`` (which
refuses anything but tensors and plain containers)::

    {"format": "ials_zoo.influence_predictor", "format_version": 1,
     "class": "GRUPredictor", "metadata_json": "<json>", "arrays": {name: tensor}}

``metadata_json`` holds the domain id (versioned, e.g. ``warehouse_v0``), agent, region spec,
d-set kind, architecture and hyper-parameters, data-set size, train/test cross-entropies,
package version and creation time.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ials_zoo._version import __version__
from ials_zoo.core.region import RegionSpec
from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.influence.base import InfluencePredictor
from ials_zoo.influence.constant import FixedPredictor, MarginalPredictor, UniformPredictor
from ials_zoo.influence.networks import ARCHS, GRUPredictor, MLPPredictor
from ials_zoo.utils import atomic_path, loads_untrusted_json

FORMAT = "ials_zoo.influence_predictor"
SET_FORMAT = "ials_zoo.influence_predictor_set"
FORMAT_VERSION = 1

_CLASSES = {
    cls.__name__: cls
    for cls in (MLPPredictor, GRUPredictor, UniformPredictor, FixedPredictor, MarginalPredictor)
}


def _package_version() -> str:
    return __version__


def _payload(predictor: InfluencePredictor) -> dict:
    import torch

    if not isinstance(predictor, InfluencePredictor):
        raise BadInputType(f"expected an InfluencePredictor, got {type(predictor).__name__}")
    cls_name = type(predictor).__name__
    if cls_name not in _CLASSES:
        raise BadInputType(f"cannot save predictor class {cls_name}")
    meta = dict(predictor.metadata)
    meta.setdefault("created", time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))
    meta["package_version"] = meta.get("package_version") or _package_version()
    meta.update(
        {
            "env_id": predictor.region.domain,
            "agent": predictor.region.agent,
            "region": predictor.region.to_dict(),
            "dset_kind": predictor.dset_kind,
            "predictor": predictor.name,
            "config": predictor._config(),
        }
    )
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "class": cls_name,
        "metadata_json": json.dumps(meta, sort_keys=True, default=_json_default),
        "arrays": {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in predictor._arrays().items()},
    }


def save_predictor(predictor: InfluencePredictor, path) -> Path:
    """Save ``predictor`` to one file (atomic), see the module docstring for the format."""
    import torch

    payload = _payload(predictor)
    path = Path(path)
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)
    return path


def save_predictor_set(predictors, path, metadata: dict | None = None) -> Path:
    """Save the predictors of several agents to one file (atomic)::

        {"format": "ials_zoo.influence_predictor_set", "format_version": 1,
         "metadata_json": "<json>", "members": [<one predictor payload per agent>]}
    """
    import torch

    predictors = list(predictors)
    payload = {"format": SET_FORMAT, "format_version": FORMAT_VERSION,
               "metadata_json": json.dumps(dict(metadata or {}), sort_keys=True, default=_json_default),
               "members": [_payload(p) for p in predictors]}
    path = Path(path)
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)
    return path


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise BadInputType(f"not JSON serialisable: {type(o).__name__}")


def _from_payload(payload, where) -> InfluencePredictor:
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise BadInput(f"not an ials_zoo influence predictor: {where} (no {FORMAT!r} header)")
    if payload.get("format_version") != FORMAT_VERSION:
        raise BadInput(
            f"{where}: influence predictor format version {payload.get('format_version')!r}, this "
            f"ials_zoo reads version {FORMAT_VERSION}"
        )
    try:
        meta = loads_untrusted_json(payload["metadata_json"])
        if not isinstance(meta, dict):
            raise BadInputType("metadata_json must hold a JSON object")
        cls = _CLASSES[payload["class"]]
        region = RegionSpec.from_dict(meta["region"])
        arrays = {k: v.numpy() for k, v in payload["arrays"].items()}
        kwargs = dict(meta.get("config", {}))
        if cls in ARCHS.values():
            return cls(region, dset_kind=meta["dset_kind"], arrays=arrays, metadata=meta, **kwargs)
        return cls(region, dset_kind=meta["dset_kind"], metadata=meta, table=arrays["table"], **kwargs)
    except (KeyError, TypeError, ValueError, AttributeError, UnicodeDecodeError) as exc:
        raise BadInput(f"not an ials_zoo influence predictor: {where} (bad content: {exc})") from None


def _torch_load(path):
    import torch

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"influence predictor file not found: {path}")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many kinds for a corrupt/foreign file
        raise BadInput(f"not an ials_zoo influence predictor: {path} ({type(exc).__name__}: {exc})") from None


def load_predictor_set(path, env_id: str | None = None) -> dict:
    """``{agent: predictor}`` from a file of :func:`save_predictor_set` (weights only: no
    pickle)."""
    payload = _torch_load(path)
    if not isinstance(payload, dict) or payload.get("format") != SET_FORMAT:
        raise BadInput(f"not an ials_zoo influence predictor set: {path}")
    if payload.get("format_version") != FORMAT_VERSION:
        raise BadInput(f"{path}: influence predictor set format version {payload.get('format_version')!r}, this "
                         f"ials_zoo reads version {FORMAT_VERSION}")
    members = payload.get("members")
    if not isinstance(members, list) or not members:
        raise BadInput(f"not an ials_zoo influence predictor set: {path} (members must be a non-empty list, got "
                         f"{type(members).__name__})")
    out = {}
    for i, member in enumerate(members):
        pred = _from_payload(member, f"{path} (member {i})")
        if env_id is not None and pred.region.domain != env_id:
            raise BadInput(f"{path} holds predictors of {pred.region.domain!r}, not {env_id!r}")
        if pred.region.agent in out:
            raise BadInput(f"{path}: two members are predictors of {pred.region.agent!r}")
        pred.source = Path(path)
        out[pred.region.agent] = pred
    return out


def load_predictor(path, env_id: str | None = None, agent: str | None = None) -> InfluencePredictor:
    """Load a predictor saved by :func:`save_predictor`.

    ``env_id``/``agent``, when given, must match the ones it was trained for (a clear
    ``ValueError`` naming both otherwise). A file that is not a predictor file (corrupt,
    truncated, something else) raises ``ValueError("not an ials_zoo influence predictor: ...")``.
    A predictor-set file (:func:`save_predictor_set`) gives ``agent``'s member.
    """
    path = Path(path)
    payload = _torch_load(path)
    if isinstance(payload, dict) and payload.get("format") == SET_FORMAT and agent is not None:
        members = load_predictor_set(path, env_id)
        if agent not in members:
            raise BadInput(f"{path} is a set of influence predictors without one for agent {agent!r} "
                           f"(it has {', '.join(sorted(members)[:5])}{', ...' if len(members) > 5 else ''})")
        return members[agent]
    pred = _from_payload(payload, path)
    region = pred.region
    if env_id is not None and region.domain != env_id:
        raise BadInput(
            f"{path} is an influence predictor for domain {region.domain!r}, not {env_id!r}"
        )
    if agent is not None and region.agent != agent:
        raise BadInput(
            f"{path} is an influence predictor for agent {region.agent!r} of {region.domain}, "
            f"not for agent {agent!r}"
        )
    pred.source = path
    return pred


__all__ = ["FORMAT", "FORMAT_VERSION", "SET_FORMAT", "load_predictor", "load_predictor_set", "save_predictor",
           "save_predictor_set"]
