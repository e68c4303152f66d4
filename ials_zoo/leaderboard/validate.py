"""Validating results: the schema, then every number against the data it summarises.

:func:`validate_result` checks the JSON Schema (``ials_zoo/leaderboard/schema.json``, draft
2020-12) and then that the result means what it says:

* every number is finite (``NaN``/``Infinity`` are refused: they are not JSON, and Python's
  parser would otherwise accept them);
* every per-seed mean and interval is recomputed from the episode scores, the overall score
  from the per-seed scores, a multi-agent episode score from the agents' returns (relative
  tolerance :data:`REL_TOL`: JSON floats round-trip exactly, this only absorbs summation
  order);
* the domain, its version and every agent exist; the track matches ``agent``/``agents``;
* ``evaluation.protocol`` is what the seeds, options and agents make it (``official`` or
  ``variant``: a result cannot claim to follow the protocol when it does not);
* a model names the file and sha256 of each seed's policy; a reference policy names none; a
  ``callable`` policy (code) is valid as a local result but is never accepted on the board.

:func:`load_result` reads a file of at most :data:`MAX_RESULT_BYTES` bytes first.
"""

from __future__ import annotations

import json
import math
import os
from importlib import resources
from pathlib import Path

import numpy as np

from ials_zoo import reference_speed
from ials_zoo.core.domains import domain_ids, get_domain
from ials_zoo.errors import BadInput
from ials_zoo.leaderboard.build import (
    MULTI,
    SCHEMA_VERSION,
    SINGLE,
    overall_metrics,
    overall_score,
    per_agent_scores,
    protocol_of,
    split_env_id,
)
from ials_zoo.stats import bootstrap_interval
from ials_zoo.utils import atomic_write_text, loads_untrusted_json, read_regular_file

REL_TOL = 1e-9
ABS_TOL = 1e-12
MAX_RESULT_BYTES = 4 * 2**20


class ResultError(BadInput):
    """A result file is malformed or inconsistent; ``field`` names the offending field."""

    def __init__(self, field: str, message: str):
        self.field = field
        super().__init__(f"{field}: {message}")


def load_schema() -> dict:
    """The result JSON Schema shipped with the package."""
    return json.loads(resources.files("ials_zoo.leaderboard").joinpath("schema.json").read_text())


def _close(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=REL_TOL, abs_tol=ABS_TOL)


def _json_path(error) -> str:
    parts = [str(p) for p in error.absolute_path]
    return ".".join(parts) if parts else "(top level)"


def check_finite(obj, where: str = "(top level)") -> None:
    """A :class:`ResultError` naming the first non-finite number inside ``obj``."""
    if isinstance(obj, float):
        if not math.isfinite(obj):
            raise ResultError(where, f"{obj!r} is not a finite number")
    elif isinstance(obj, dict):
        for k, v in obj.items():
            check_finite(v, k if where == "(top level)" else f"{where}.{k}")
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            check_finite(v, f"{where}.{i}")


def _schema_check(data: dict) -> None:
    import jsonschema

    validator = jsonschema.Draft202012Validator(load_schema())
    errors = sorted(validator.iter_errors(data), key=lambda e: (len(list(e.absolute_path)), str(e.absolute_path)))
    if errors:
        err = errors[0]
        field = _json_path(err)
        if err.validator == "required":
            missing = err.message.split("'")[1] if "'" in err.message else err.message
            field = f"{field}.{missing}" if field != "(top level)" else missing
        if err.validator == "additionalProperties" and isinstance(err.instance, dict):
            extra = sorted(set(err.instance) - set(err.schema.get("properties", {})))
            names = ",".join(extra)
            field = f"{field}.{names}" if field != "(top level)" else names
        raise ResultError(field, f"schema violation: {err.message}")


def validate_result(data, local: bool = False) -> dict:
    """Check ``data`` (module docstring); return it, or raise :class:`ResultError` naming the
    offending field. ``local``: a result of a run on the user's own files (a network of their
    own: the domain's ``file_options``), which the run writes and keeps; anything that reads a
    result as an entry (submit, verify, the board) leaves ``local`` off and refuses such files."""
    if not isinstance(data, dict):
        raise ResultError("(top level)", f"a result must be a JSON object, got {type(data).__name__}")
    if data.get("schema_version") != SCHEMA_VERSION:
        raise ResultError("schema_version", f"{data.get('schema_version')!r}; this ials_zoo reads version "
                          f"{SCHEMA_VERSION} (re-evaluate the policy with `ials-zoo evaluate`)")
    check_finite(data)
    _schema_check(data)

    domain = _check_domain(data, local)
    _check_track_and_protocol(data)
    kind = data["policy"]["kind"]
    if kind in ("random", "scripted"):
        # a reference policy is a reference entry: nothing was trained, and it is named as itself
        if data["training"] is not None or data["algorithm"] != kind or data["trained_agents"]:
            raise ResultError("training", f"the reference policy {kind!r} makes a reference entry: training null, "
                              f"algorithm {kind!r}, no trained agents")
    if kind == "rule":
        _check_rule(data, domain)
    if "provenance" in data and kind != "model":
        raise ResultError("provenance", "only trained policies have a provenance")
    if "retrained" in data:
        reproduce = (data["training"] or {}).get("reproduce")
        if kind != "model" or reproduce is None:
            raise ResultError("retrained", "only an entry that records its training command can have been re-trained")
        if not set(data["retrained"]["seeds"]) <= set(data["training"]["seeds"]):
            raise ResultError("retrained.seeds", f"{data['retrained']['seeds']} are not among the training seeds")
    _check_seed_scores(data, kind)
    _check_overall_score(data)
    _check_metrics(data, domain)
    _check_training(data, kind)
    return data


def _check_domain(data: dict, local: bool = False):
    """The domain, its version, its GS options and its agents exist; return the domain. Options
    that name the user's own files are a local result's only (:func:`validate_result`)."""
    env_id = data["env_id"]
    if env_id not in domain_ids():
        raise ResultError("env_id", f"unknown domain {env_id!r}; known: {', '.join(domain_ids())}")
    domain_name, version = split_env_id(env_id)
    if data["domain"] != domain_name:
        raise ResultError("domain", f"{data['domain']!r} does not match env_id {env_id!r}")
    if data["domain_version"] != version:
        raise ResultError("domain_version", f"{data['domain_version']} does not match env_id {env_id!r}")
    ev = data["evaluation"]
    domain = get_domain(env_id)
    files = [k for k in ev["options"] if k in domain.file_options]
    if files and not local:
        raise ResultError("evaluation.options", f"{files} name files of a network of your own: the result stays with "
                          f"its run (the board keeps {env_id}'s own scenarios, and never reads a file a result names)")
    unknown = [k for k in ev["options"] if k not in domain.gs_options and k not in files]
    if unknown:
        raise ResultError("evaluation.options", f"{unknown} {'is not a GS option' if len(unknown) == 1 else 'are not GS options'} "
                          f"of {env_id} (its options: {', '.join(domain.gs_options) or 'none'})")
    try:
        agents_of_domain = domain.agents(**ev["options"])
    except Exception as exc:  # the domain's package failed to import, or bad options
        raise ResultError("env_id", f"domain {env_id!r} is not available with these options: {exc}") from None
    for field in ("agents", "trained_agents"):
        for i, a in enumerate(data[field]):
            if a not in agents_of_domain:
                raise ResultError(f"{field}.{i}", f"{a!r} is not an agent of {env_id}")
    if len(set(data["agents"])) != len(data["agents"]):
        raise ResultError("agents", "agents repeat")
    return domain


def _check_track_and_protocol(data: dict) -> None:
    """``agent``/``agents``/``neighbours`` match the track; the seeds make ``evaluation.protocol``."""
    ev = data["evaluation"]
    env_id = data["env_id"]
    track = data["track"]
    if track == SINGLE and (data["agent"] is None or data["agents"] != [data["agent"]]):
        raise ResultError("agent", "a single-agent result scores one agent: agent, and agents == [agent]")
    if track == MULTI and data["agent"] is not None:
        raise ResultError("agent", "a multi-agent result has agent null (its agents are in 'agents')")
    if (track == MULTI) != ("per_agent_scores" in data):
        raise ResultError("per_agent_scores", "present exactly on the multi-agent track")
    if (track == SINGLE) != (ev["neighbours"] == "scripted"):
        raise ResultError("evaluation.neighbours", "'scripted' on the single-agent track, 'learners' on the multi-agent one")

    if len(ev["seeds"]) != ev["episodes"]:
        raise ResultError("evaluation.seeds", f"{len(ev['seeds'])} seeds for {ev['episodes']} episodes")
    if len(set(ev["seeds"])) != len(ev["seeds"]):
        raise ResultError("evaluation.seeds", "evaluation seeds repeat")
    want = protocol_of(track, env_id, data["agents"], ev["seeds"], ev["options"])
    if ev["protocol"] != want:
        raise ResultError("evaluation.protocol", f"{ev['protocol']!r}, but these seeds, options and agents make "
                          f"it {want!r}")


def _check_rule(data: dict, domain) -> None:
    """A rule is a reference entry of the multi-agent track, named as itself, of its domain."""
    name = data["policy"]["name"]
    if name not in domain.rules:
        raise ResultError("policy.name", f"{data['env_id']} has no rule {name!r}; its rules: {', '.join(domain.rules)}")
    if data["track"] != MULTI:
        raise ResultError("track", "a rule drives every agent: multi-agent track only")
    if data["training"] is not None or data["algorithm"] != name or data["trained_agents"]:
        raise ResultError("training", f"the rule {name!r} makes a reference entry: training null, algorithm "
                          f"{name!r}, no trained agents")


def _check_seed_scores(data: dict, kind: str) -> None:
    """Each seed's returns (and a multi-agent episode's agents' returns), mean, interval and policy file."""
    ev = data["evaluation"]
    track = data["track"]
    for i, s in enumerate(data["scores"]):
        where = f"scores.{i}"
        if len(s["returns"]) != ev["episodes"]:
            raise ResultError(f"{where}.returns", f"{len(s['returns'])} returns for {ev['episodes']} episodes")
        if track == MULTI:
            per = s.get("per_agent_returns")
            if per is None or list(per) != data["agents"]:
                raise ResultError(f"{where}.per_agent_returns", "one list per agent, in the order of 'agents'")
            for a, values in per.items():
                if len(values) != ev["episodes"]:
                    raise ResultError(f"{where}.per_agent_returns.{a}", f"{len(values)} returns for {ev['episodes']} episodes")
            joint = np.mean(np.array([per[a] for a in data["agents"]], dtype=np.float64), axis=0)
            for e, (x, y) in enumerate(zip(s["returns"], joint)):
                if not _close(x, float(y)):
                    raise ResultError(f"{where}.returns.{e}", f"{x!r} is not the mean of the agents' returns ({y!r})")
        elif "per_agent_returns" in s:
            raise ResultError(f"{where}.per_agent_returns", "only on the multi-agent track")
        mean, lo, hi = bootstrap_interval(s["returns"])
        for key, value in (("mean", mean), ("ci_low", lo), ("ci_high", hi)):
            if not _close(s[key], value):
                raise ResultError(f"{where}.{key}", f"{s[key]!r} does not match the returns ({value!r})")
        if kind in ("random", "scripted", "rule") and (s["policy_sha256"] is not None or s["policy_file"] is not None):
            raise ResultError(f"{where}.policy_sha256", f"must be null for the reference policy {kind!r}")
        if kind == "model" and (s["policy_sha256"] is None or not s["policy_file"]):
            raise ResultError(f"{where}.policy_sha256", "a model needs the file and the sha256 of its policy")


def _check_overall_score(data: dict) -> None:
    """The overall score (and a multi-agent result's per-agent scores) from the per-seed scores."""
    track = data["track"]
    want_score = overall_score(data["scores"])
    for key in ("mean", "ci_low", "ci_high"):
        if not _close(data["score"][key], want_score[key]):
            raise ResultError(f"score.{key}", f"{data['score'][key]!r} does not match the per-seed scores ({want_score[key]!r})")
    if data["score"]["ci_over"] != want_score["ci_over"]:
        raise ResultError("score.ci_over", f"{data['score']['ci_over']!r}, expected {want_score['ci_over']!r}")
    if track == MULTI:
        want_agents = per_agent_scores(data["scores"])
        if list(data["per_agent_scores"]) != list(want_agents) or not all(
                _close(data["per_agent_scores"][a], v) for a, v in want_agents.items()):
            raise ResultError("per_agent_scores", "does not match the per-agent returns")


def _check_training(data: dict, kind: str) -> None:
    """A model's training record matches its seeds; learning curves do not go back in env_steps."""
    training = data["training"]
    if training is None:
        if kind == "model":
            raise ResultError("training", "a trained model needs its training record")
    else:
        seeds = [s["seed"] for s in data["scores"]]
        if seeds != training["seeds"]:
            raise ResultError("scores", f"per-seed scores {seeds} do not match training.seeds {training['seeds']}")
        _check_reference(training)
    for i, curve in enumerate(data["learning_curves"]):
        steps = [p["env_steps"] for p in curve["points"]]
        if steps != sorted(steps):
            raise ResultError(f"learning_curves.{i}.points", "env_steps must not decrease")


def _check_reference(training: dict) -> None:
    """A one-seed run's ``training.reference`` agrees with its own timings: under load exactly
    when they moved by more than 20%, and its reference seconds its wall-clock scaled by them
    (a merged entry's are its seeds', :func:`ials_zoo.reference_speed.merged`)."""
    ref = training.get("reference")
    if ref is None:
        return
    if "reference_seconds" in ref and not ref["seconds"]:
        raise ResultError("training.reference.seconds", "reference seconds need the timings they come from")
    if len(training["seeds"]) != 1:
        return
    if ref["under_load"] != reference_speed.under_load(ref):
        raise ResultError("training.reference.under_load", f"{ref['under_load']} does not say what its timings say "
                          f"({reference_speed.under_load(ref)}: under load when they move by more than 20%)")
    total = float(training["wall_clock_seconds"]) + float(training["aip_seconds"])
    if "reference_seconds" in ref and not math.isclose(
            ref["reference_seconds"], reference_speed.reference_seconds(total, ref["seconds"]), rel_tol=1e-3, abs_tol=1e-2):
        raise ResultError("training.reference.reference_seconds", f"{ref['reference_seconds']} is not the wall-clock "
                          f"({total:.3f} s) scaled by its timings ({reference_speed.reference_seconds(total, ref['seconds'])})")


def _check_metrics(data: dict, domain) -> None:
    """Physical metrics: only the domain's names, each within the values it can take
    (:meth:`~ials_zoo.core.domains.Domain.metric_range`: a negative age is refused), an
    interval around each mean, and the top level recomputed from the seeds (as the score)."""
    known = domain.metrics
    places = [(f"scores.{i}.metrics", s.get("metrics")) for i, s in enumerate(data["scores"])]
    for where, metrics in places + [("metrics", data.get("metrics"))]:
        for name, value in (metrics or {}).items():
            if name not in known:
                raise ResultError(f"{where}.{name}", f"not a metric of {data['env_id']} (its metrics: "
                                  f"{', '.join(known) or 'none'})")
            if not value["ci_low"] <= value["mean"] <= value["ci_high"]:
                raise ResultError(f"{where}.{name}", "the mean must lie in [ci_low, ci_high]")
            if "episodes" in value:
                _check_metric_episodes(data, f"{where}.{name}", value)
            low, high = domain.metric_range(name)
            # a seed's interval is over its episodes (inside the range); the top level's is a
            # t interval over seeds, which may reach past it
            checked = ("mean",) if where == "metrics" else ("mean", "ci_low", "ci_high")
            for key in checked:
                if not low <= value[key] <= high:
                    raise ResultError(f"{where}.{name}.{key}", f"{value[key]!r} is not a value {name} can take "
                                      f"([{low:g}, {high:g}])")
    want = overall_metrics(data["scores"])
    got = data.get("metrics")
    if (want is None) != (got is None) or (want is not None and (list(want) != list(got) or not all(
            _close(got[n][k], want[n][k]) for n in want for k in ("mean", "ci_low", "ci_high")))):
        raise ResultError("metrics", "does not match the per-seed metrics (every seed carries the same metrics, "
                          "and the top level is their mean with a t interval over seeds)")


def _check_metric_episodes(data: dict, where: str, value: dict) -> None:
    """A metric's episodes: one value per evaluated episode, whose mean, interval and median
    are the ones it claims."""
    values = value["episodes"]
    if len(values) != data["evaluation"]["episodes"]:
        raise ResultError(f"{where}.episodes", f"{len(values)} values for {data['evaluation']['episodes']} episodes")
    mean, lo, hi = bootstrap_interval(values)
    for key, want in (("mean", mean), ("ci_low", lo), ("ci_high", hi), ("median", float(np.median(values)))):
        if key in value and not _close(value[key], want):
            raise ResultError(f"{where}.{key}", f"{value[key]!r} does not match its episodes ({want!r})")


def parse_result_text(text: str, where: str) -> dict:
    """JSON as :func:`~ials_zoo.utils.loads_untrusted_json` parses it (depth, integer size and
    NaN limits), or a :class:`ResultError` naming ``where``."""
    try:
        return loads_untrusted_json(text)
    except (ValueError, UnicodeDecodeError) as exc:
        raise ResultError("(file)", f"{where} is not valid JSON: {exc}") from None


def load_result(path: str | os.PathLike, follow_links: bool = True) -> dict:
    """Read and validate a result file (a :class:`ResultError` naming the file for malformed
    JSON, a file over :data:`MAX_RESULT_BYTES`, anything but a regular file -- a fifo, a
    device, and with ``follow_links=False`` a symbolic link -- or an inconsistent result)."""
    path = Path(path)
    try:
        raw = read_regular_file(path, MAX_RESULT_BYTES, follow_links=follow_links)
    except ValueError as exc:
        raise ResultError("(file)", f"{exc}; a result is a regular file of at most {MAX_RESULT_BYTES:,} bytes") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ResultError("(file)", f"cannot read {str(path)!r}: {exc}") from None
    return validate_result(parse_result_text(text, repr(str(path))))


def write_result(path: str | os.PathLike, data: dict, local: bool = False) -> Path:
    """Validate (``local``: :func:`validate_result`'s) and write a result atomically (any path;
    not a leaderboard submission)."""
    validate_result(data, local)
    atomic_write_text(path, json.dumps(data, indent=2, allow_nan=False) + "\n")
    return Path(path)


__all__ = ["MAX_RESULT_BYTES", "REL_TOL", "ResultError", "check_finite", "load_result", "load_schema",
           "validate_result", "write_result"]
