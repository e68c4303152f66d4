"""Leaderboard results: build, validate, submit, show, render and verify.

A *result* is one JSON file (schema: ``ials_zoo/leaderboard_schema.json``, documented in
``leaderboard/SCHEMA.md``): the GS score of one policy for one agent of one domain, measured
with the protocol of :mod:`ials_zoo.evaluation`, together with how the policy was trained.

:func:`validate_result` checks the schema (jsonschema, draft 2020-12) *and* the consistency of
the numbers: every per-seed mean and 95% interval is recomputed from the episodic returns, the
overall score from the per-seed scores, and the domain, its version and the agent must exist.
Numbers must agree within :data:`REL_TOL` (relative, floor 1e-9 absolute) -- JSON floats
round-trip exactly, so this only absorbs summation-order differences.

:func:`submit` writes an accepted result into ``<dir>/results/`` under a unique name derived
from its content; it never overwrites a file and refuses a result whose content (everything
but ``created``/``submitter``/``notes``) is already on the board. The write is atomic: an
interrupted submission leaves the board as it was.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
import os
import platform
import re
from collections.abc import Iterable, Sequence
from importlib import resources
from pathlib import Path

from ials_zoo.utils import atomic_path, atomic_write_text

REL_TOL = 1e-6
RESULTS_SUBDIR = "results"
_VOLATILE = ("created", "submitter", "notes")


class ResultError(ValueError):
    """A result file is malformed or inconsistent; ``field`` names the offending field."""

    def __init__(self, field: str, message: str):
        self.field = field
        super().__init__(f"{field}: {message}")


# --------------------------------------------------------------------------------------------
# Building results


def load_schema() -> dict:
    """The result JSON Schema shipped with the package."""
    text = resources.files("ials_zoo").joinpath("leaderboard_schema.json").read_text()
    return json.loads(text)


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
    try:
        import torch

        torch_version = torch.__version__
    except ImportError:  # pragma: no cover - torch is a dependency
        torch_version = None
    return {
        "platform": platform.platform(),
        "processor": processor or "unknown",
        "cpu_count": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
        "python": platform.python_version(),
        "torch": torch_version,
    }


def split_env_id(env_id: str) -> tuple[str, int]:
    """``"warehouse_v0"`` -> ``("warehouse", 0)``."""
    m = re.fullmatch(r"([a-z][a-z0-9_]*)_v([0-9]+)", env_id or "")
    if not m:
        raise ValueError(f"env_id {env_id!r} is not of the form '<domain>_v<version>'")
    return m.group(1), int(m.group(2))


def now_iso() -> str:
    return _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def overall_score(per_seed_means: Sequence[float], single: dict | None = None) -> dict:
    """The ``score`` field: with one training seed, that seed's mean and t-interval over
    episodes; with several, the mean of the seed means and the t-interval over seeds."""
    from ials_zoo.evaluation import mean_ci

    if len(per_seed_means) == 1 and single is not None:
        return {"mean": single["mean"], "ci_low": single["ci_low"], "ci_high": single["ci_high"],
                "ci_over": "episodes"}
    mean, lo, hi = mean_ci(per_seed_means)
    return {"mean": mean, "ci_low": lo, "ci_high": hi, "ci_over": "seeds"}


def make_result(evaluations: Sequence, *, algorithm: str, training: dict | None = None,
                training_seeds: Sequence[int | None] | None = None,
                learning_curves: Sequence[dict] = (), trained_agents: Sequence[str] | None = None,
                submitter: str = "", notes: str = "") -> dict:
    """Build a result dict from one :class:`~ials_zoo.evaluation.EvaluationResult` per
    training seed (all for the same domain, agent and evaluation seeds)."""
    import ials_zoo

    if not evaluations:
        raise ValueError("make_result needs at least one evaluation")
    first = evaluations[0]
    for ev in evaluations[1:]:
        if (ev.env_id, ev.agent, ev.seeds) != (first.env_id, first.agent, first.seeds):
            raise ValueError("all evaluations of a result must share domain, agent and seeds")
    seeds = list(training_seeds) if training_seeds is not None else [None] * len(evaluations)
    if len(seeds) != len(evaluations):
        raise ValueError(f"{len(seeds)} training seeds for {len(evaluations)} evaluations")
    domain, version = split_env_id(first.env_id)
    scores = [
        {"seed": s, "policy_file": ev.policy_file, "policy_sha256": ev.policy_sha256,
         "mean": ev.mean, "ci_low": ev.ci_low, "ci_high": ev.ci_high, "returns": list(ev.returns)}
        for s, ev in zip(seeds, evaluations)
    ]
    evaluation = {
        "simulator": "gs", "neighbours": "scripted", "episodes": len(first.seeds),
        "seeds": list(first.seeds), "ci_level": 0.95, "ci_method": "student-t",
        "deterministic": bool(first.deterministic),
    }
    if first.options:
        evaluation["options"] = dict(first.options)
    return {
        "schema_version": 1,
        "env_id": first.env_id,
        "domain": domain,
        "domain_version": version,
        "agent": first.agent,
        "trained_agents": list(trained_agents if trained_agents is not None
                               else ([first.agent] if training else [])),
        "policy": {"name": first.policy, "kind": first.policy_kind,
                   "frame_stack": int(first.frame_stack), "deterministic": bool(first.deterministic)},
        "algorithm": algorithm,
        "training": training,
        "hardware": hardware_info(),
        "evaluation": evaluation,
        "scores": scores,
        "score": overall_score([s["mean"] for s in scores], scores[0]),
        "learning_curves": list(learning_curves),
        "package_version": ials_zoo.__version__,
        "created": now_iso(),
        "submitter": submitter,
        "notes": notes,
    }


def reference_result(env_id: str, agent: str, policy: str, episodes: int = 20,
                     submitter: str = "", notes: str = "", **options) -> dict:
    """Evaluate a reference policy (``"random"`` or ``"scripted"``) and build its result."""
    from ials_zoo.evaluation import REFERENCE_POLICIES, evaluate

    if policy not in REFERENCE_POLICIES:
        raise ValueError(f"reference policy must be one of {REFERENCE_POLICIES}, got {policy!r}")
    ev = evaluate(env_id, agent, policy, episodes=episodes, **options)
    return make_result([ev], algorithm=policy, submitter=submitter, notes=notes)


def merge_results(results: Sequence[dict], submitter: str | None = None,
                  notes: str | None = None) -> dict:
    """Combine single-seed results of the same experiment (same domain, agent, algorithm,
    training simulator and evaluation protocol; different training seeds) into one result
    with a score per seed and the overall score over seeds.

    ``training.env_steps`` must agree; ``wall_clock_seconds`` and ``aip_seconds`` become the
    means over seeds (documented in SCHEMA.md)."""
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

    same(lambda r: r["env_id"], "env_id")
    same(lambda r: r["agent"], "agent")
    same(lambda r: r["algorithm"], "algorithm")
    same(lambda r: r["policy"]["kind"], "policy.kind")
    same(lambda r: r["policy"]["frame_stack"], "policy.frame_stack")
    same(lambda r: r["evaluation"], "evaluation")
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
    merged = dict(first, training=training, scores=scores,
                  score=overall_score([s["mean"] for s in scores], scores[0]),
                  learning_curves=[c for r in results for c in r["learning_curves"]],
                  created=now_iso(),
                  submitter=first["submitter"] if submitter is None else submitter,
                  notes=first["notes"] if notes is None else notes)
    return validate_result(merged)


# --------------------------------------------------------------------------------------------
# Validation


def _close(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=REL_TOL, abs_tol=1e-9)


def _json_path(error) -> str:
    parts = [str(p) for p in error.absolute_path]
    return ".".join(parts) if parts else "(top level)"


def validate_result(data) -> dict:
    """Check ``data`` against the schema and for consistency; return it, or raise
    :class:`ResultError` naming the offending field."""
    import jsonschema

    from ials_zoo.core.domains import domain_ids, get_domain
    from ials_zoo.evaluation import mean_ci

    if not isinstance(data, dict):
        raise ResultError("(top level)", f"a result must be a JSON object, got {type(data).__name__}")
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

    env_id = data["env_id"]
    if env_id not in domain_ids():
        raise ResultError("env_id", f"unknown domain {env_id!r}; known: {', '.join(domain_ids())}")
    domain, version = split_env_id(env_id)
    if data["domain"] != domain:
        raise ResultError("domain", f"{data['domain']!r} does not match env_id {env_id!r}")
    if data["domain_version"] != version:
        raise ResultError("domain_version", f"{data['domain_version']} does not match env_id {env_id!r}")
    try:
        agents = list(get_domain(env_id).possible_agents())
    except Exception as exc:  # the domain's package failed to import or build
        raise ResultError("env_id", f"domain {env_id!r} is not available: {exc}") from None
    if data["agent"] not in agents:
        raise ResultError("agent", f"{data['agent']!r} is not an agent of {env_id}")
    for i, a in enumerate(data["trained_agents"]):
        if a not in agents:
            raise ResultError(f"trained_agents.{i}", f"{a!r} is not an agent of {env_id}")

    ev = data["evaluation"]
    if len(ev["seeds"]) != ev["episodes"]:
        raise ResultError("evaluation.seeds", f"{len(ev['seeds'])} seeds for {ev['episodes']} episodes")
    kind = data["policy"]["kind"]
    for i, s in enumerate(data["scores"]):
        where = f"scores.{i}"
        if len(s["returns"]) != ev["episodes"]:
            raise ResultError(f"{where}.returns", f"{len(s['returns'])} returns for {ev['episodes']} episodes")
        mean, lo, hi = mean_ci(s["returns"])
        for key, want in (("mean", mean), ("ci_low", lo), ("ci_high", hi)):
            if not _close(s[key], want):
                raise ResultError(f"{where}.{key}", f"{s[key]!r} does not match the returns ({want!r})")
        if kind in ("random", "scripted") and s["policy_sha256"] is not None:
            raise ResultError(f"{where}.policy_sha256", f"must be null for the reference policy {kind!r}")
        if kind == "model" and s["policy_sha256"] is None:
            raise ResultError(f"{where}.policy_sha256", "a model policy needs the sha256 of its file")
    want = overall_score([s["mean"] for s in data["scores"]], data["scores"][0])
    for key in ("mean", "ci_low", "ci_high"):
        if not _close(data["score"][key], want[key]):
            raise ResultError(f"score.{key}", f"{data['score'][key]!r} does not match the per-seed scores ({want[key]!r})")
    if data["score"]["ci_over"] != want["ci_over"]:
        raise ResultError("score.ci_over", f"{data['score']['ci_over']!r}, expected {want['ci_over']!r}")
    if not data["score"]["ci_low"] <= data["score"]["mean"] <= data["score"]["ci_high"]:
        raise ResultError("score", "mean lies outside its confidence interval")

    training = data["training"]
    if training is None:
        if kind == "model":
            raise ResultError("training", "a trained model needs its training record")
    else:
        seeds = [s["seed"] for s in data["scores"]]
        if seeds != training["seeds"]:
            raise ResultError("scores", f"per-seed scores {seeds} do not match training.seeds {training['seeds']}")
    for i, curve in enumerate(data["learning_curves"]):
        steps = [p["env_steps"] for p in curve["points"]]
        if steps != sorted(steps):
            raise ResultError(f"learning_curves.{i}.points", "env_steps must not decrease")
    return data


def load_result(path: str | os.PathLike) -> dict:
    """Read and validate a result file (ResultError for malformed JSON too)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ResultError("(file)", f"cannot read {str(path)!r}: {exc}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ResultError("(file)", f"{str(path)!r} is not valid JSON: {exc}") from None
    return validate_result(data)


def write_result(path: str | os.PathLike, data: dict) -> Path:
    """Validate and write a result atomically (any path; not a leaderboard submission)."""
    validate_result(data)
    atomic_write_text(path, json.dumps(data, indent=2) + "\n")
    return Path(path)


# --------------------------------------------------------------------------------------------
# The board


def content_hash(data: dict) -> str:
    """sha256 of a result without its volatile fields (what makes two results duplicates)."""
    core = {k: v for k, v in data.items() if k not in _VOLATILE}
    return hashlib.sha256(json.dumps(core, sort_keys=True).encode()).hexdigest()


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9.-]+", "-", str(text)).strip("-")[:40] or "x"


def entry_name(data: dict) -> str:
    """The file name of a result on the board (unique by content)."""
    sim = (data["training"] or {}).get("simulator", "none")
    sim = Path(sim).stem if sim.endswith(".pt") else sim
    return "__".join([data["env_id"], data["agent"], _slug(data["algorithm"]), _slug(sim),
                      content_hash(data)[:12]]) + ".json"


def load_entries(directory: str | os.PathLike = "leaderboard") -> list[tuple[Path, dict]]:
    """All results on the board, as ``(path, data)``, sorted by file name."""
    results = Path(directory) / RESULTS_SUBDIR
    out = []
    for p in sorted(results.glob("*.json")) if results.is_dir() else []:
        out.append((p, json.loads(p.read_text())))
    return out


def submit(path: str | os.PathLike, directory: str | os.PathLike = "leaderboard") -> Path:
    """Validate the result at ``path`` and add it to the board; return its new path.

    Raises ResultError for a malformed, inconsistent or duplicate result; the board is left
    untouched in every failure (atomic write, never an overwrite)."""
    data = load_result(path)
    digest = content_hash(data)
    for p, other in load_entries(directory):
        if content_hash(other) == digest:
            raise ResultError("(file)", f"duplicate: the same result is already on the board as {p.name}")
    dest = Path(directory) / RESULTS_SUBDIR / entry_name(data)
    if dest.exists():
        raise ResultError("(file)", f"{dest} already exists; refusing to overwrite it")
    with atomic_path(dest) as tmp:
        tmp.write_text(json.dumps(data, indent=2) + "\n")
    return dest


def _training_label(data: dict) -> str:
    t = data["training"]
    if t is None:
        return "-"
    return t["simulator"]


def _total_seconds(data: dict) -> float | None:
    t = data["training"]
    if t is None:
        return None
    return float(t["wall_clock_seconds"]) + float(t["aip_seconds"])


def table_rows(entries: Iterable[tuple[Path, dict]]) -> dict[tuple[str, str], list[dict]]:
    """Entries grouped by (env_id, agent), each group sorted by score (best first)."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for p, d in entries:
        groups.setdefault((d["env_id"], d["agent"]), []).append(dict(d, _file=p.name))
    for rows in groups.values():
        rows.sort(key=lambda d: -d["score"]["mean"])
    return dict(sorted(groups.items()))


def _fmt_duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.2f} h"


def _fmt_row(d: dict) -> list[str]:
    s = d["score"]
    t = d["training"]
    total = _total_seconds(d)
    return [
        d["algorithm"],
        _training_label(d),
        f"{s['mean']:.2f}",
        f"[{s['ci_low']:.2f}, {s['ci_high']:.2f}]",
        str(len(d["scores"])) if t else "-",
        f"{d['evaluation']['episodes']}",
        f"{t['env_steps']:,}" if t else "-",
        _fmt_duration(total) if total is not None else "-",
        d["created"][:10],
    ]


HEADER = ["policy / algorithm", "trained on", "GS score", "95% CI", "seeds", "episodes",
          "env steps", "wall-clock (+AIP)", "date"]


def show(directory: str | os.PathLike = "leaderboard") -> str:
    """A plain-text table of the board, per domain and agent, sorted by score."""
    lines = []
    for (env_id, agent), rows in table_rows(load_entries(directory)).items():
        lines.append(f"{env_id} / {agent}")
        table = [HEADER] + [_fmt_row(d) for d in rows]
        widths = [max(len(r[i]) for r in table) for i in range(len(HEADER))]
        for r in table:
            lines.append("  " + "  ".join(c.ljust(w) for c, w in zip(r, widths)))
        lines.append("")
    return "\n".join(lines) if lines else "(the leaderboard is empty)"


_README_HEAD = """# ials_zoo leaderboard

GS score = mean episodic return of one agent on the global simulator with every other agent
scripted, over the fixed evaluation seeds 10000, 10001, ... (one episode each), with a 95%
Student-t confidence interval (over episodes for one training seed, over seeds for several).
Protocol: `ials_zoo/evaluation.py`; result format: [SCHEMA.md](SCHEMA.md).

Submit a result: `ials-zoo leaderboard submit result.json`; re-score it:
`ials-zoo leaderboard verify leaderboard/results/<file>.json`; regenerate this page:
`ials-zoo leaderboard render`. This file is generated: do not edit it by hand (its write-up
section is copied from [writeup.md](writeup.md)).
"""
WRITEUP = "writeup.md"


def _plot(directory: Path, env_id: str, agent: str, rows: list[dict]) -> str | None:
    curves = [d for d in rows if d["learning_curves"]]
    if not curves:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    longest = max(p["wall_clock_seconds"] for d in curves for c in d["learning_curves"] for p in c["points"])
    unit, scale = ("hours", 3600.0) if longest >= 7200 else ("minutes", 60.0)
    # One colour per (algorithm, simulator, budget); its seeds share it (a study submits one
    # result per seed), with one legend entry that counts them.
    kinds = {}
    for d in curves:
        key = (d["algorithm"], _training_label(d), d["training"]["env_steps"])
        kinds.setdefault(key, []).append(d)
    for i, ((algo, sim, steps), ds) in enumerate(kinds.items()):
        color = f"C{i % 10}"
        n = sum(len(d["learning_curves"]) for d in ds)
        label = f"{algo} on {sim}, {steps:,} steps" + (f" ({n} seeds)" if n > 1 else "")
        for d in ds:
            for c in d["learning_curves"]:
                # curve wall-clock already includes the AIP's collection + training time
                xs = [p["wall_clock_seconds"] / scale for p in c["points"]]
                ys = [p["mean"] for p in c["points"]]
                ax.plot(xs, ys, marker="o", ms=2, lw=1, color=color, label=label)
                if n == 1:
                    ax.fill_between(xs, [p["ci_low"] for p in c["points"]], [p["ci_high"] for p in c["points"]],
                                    alpha=0.2, color=color)
                label = None
    for d in rows:
        if d["training"] is None:
            ax.axhline(d["score"]["mean"], ls="--", lw=1, color="grey")
            ax.text(ax.get_xlim()[0], d["score"]["mean"], f" {d['algorithm']}", va="bottom", fontsize=8)
    ax.set_xlabel(f"wall-clock {unit} (training + AIP data collection and training)")
    ax.set_ylabel("GS mean episodic return")
    ax.set_title(f"{env_id} / {agent}")
    ax.legend(fontsize=7)
    fig.tight_layout()
    name = f"{env_id}__{agent}.png"
    with atomic_path(directory / "plots" / name, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    return f"plots/{name}"


def render(directory: str | os.PathLike = "leaderboard") -> Path:
    """Regenerate ``<dir>/README.md`` (tables per domain and agent) and ``<dir>/plots/*.png``
    (GS score vs wall-clock for entries with learning curves)."""
    directory = Path(directory)
    parts = [_README_HEAD]
    writeup = directory / WRITEUP
    if writeup.is_file():
        parts.append("\n" + writeup.read_text().strip() + "\n")
    groups = table_rows(load_entries(directory))
    if not groups:
        parts.append("\n(no results yet)\n")
    current = None
    for (env_id, agent), rows in groups.items():
        if env_id != current:
            parts.append(f"\n## {env_id}\n")
            current = env_id
        parts.append(f"\n### {agent}\n\n")
        parts.append("| " + " | ".join(HEADER + ["file"]) + " |\n")
        parts.append("|" + "---|" * (len(HEADER) + 1) + "\n")
        for d in rows:
            parts.append("| " + " | ".join(_fmt_row(d) + [f"[json](results/{d['_file']})"]) + " |\n")
        plot = _plot(directory, env_id, agent, rows)
        if plot:
            parts.append(f"\n![{env_id} {agent}]({plot})\n")
    out = directory / "README.md"
    atomic_write_text(out, "".join(parts))
    return out


# --------------------------------------------------------------------------------------------
# Verification


def verify(path: str | os.PathLike, policies: Sequence[str] | None = None,
           progress: bool = False) -> list[dict]:
    """Re-score the policy of a result on the GS with the result's own evaluation protocol.

    For each per-seed score, the policy (reference name, the recorded file, or the matching
    entry of ``policies``) is evaluated again on the recorded episode seeds; the check passes
    when the claimed mean lies within the re-measured 95% interval (widened by the
    :data:`REL_TOL` tolerance). A model file must have the recorded sha256. Returns one report
    dict per seed with ``ok``, ``claimed``, ``measured``, ``ci``."""
    from ials_zoo.evaluation import evaluate, sha256_file

    path = Path(path)
    data = load_result(path)
    kind = data["policy"]["kind"]
    if policies is not None and len(policies) != len(data["scores"]):
        raise ValueError(f"{len(policies)} policy files given for {len(data['scores'])} per-seed scores")
    ev = data["evaluation"]
    reports = []
    for i, s in enumerate(data["scores"]):
        if kind in ("random", "scripted"):
            spec = kind
        elif kind == "callable":
            spec = data["policy"]["name"]
        else:
            spec = policies[i] if policies else s["policy_file"]
            if not spec:
                raise ValueError(f"scores.{i}: no policy file recorded; pass it explicitly")
            if not os.path.exists(spec) and (path.parent / spec).exists():
                spec = str(path.parent / spec)
            if not os.path.exists(spec):
                raise ValueError(f"scores.{i}: policy file {spec!r} not found; pass it explicitly")
            digest = sha256_file(spec)
            if digest != s["policy_sha256"]:
                raise ValueError(f"scores.{i}.policy_sha256: {spec!r} has sha256 {digest}, the "
                                 f"result claims {s['policy_sha256']}")
        res = evaluate(data["env_id"], data["agent"], spec, seeds=ev["seeds"],
                       deterministic=ev["deterministic"], frame_stack=data["policy"]["frame_stack"],
                       progress=progress, **ev.get("options", {}))
        tol = REL_TOL * max(1.0, abs(res.mean))
        ok = res.ci_low - tol <= s["mean"] <= res.ci_high + tol
        reports.append({"seed": s["seed"], "claimed": s["mean"], "measured": res.mean,
                        "ci": [res.ci_low, res.ci_high], "ok": bool(ok),
                        "exact": _close(res.mean, s["mean"])})
    return reports
