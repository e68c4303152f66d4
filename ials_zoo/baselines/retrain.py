"""Re-training an entry: its recorded training command is run again for some of its training
seeds, and the check passes only when each re-trained policy file is the submitted one.

Our training is bitwise reproducible for a seed on one platform (``tests/test_exact_resume.py``
holds it across resumes), so a training claim can be re-executed, not only read. A result's
``training.reproduce`` records the command (``ials-zoo train ...`` with every argument that
differs from its default, without the run's folder), the package version and commit, and the
platform (:func:`reproduce_record`). :func:`retrain` runs that command for the first ``seeds``
training seeds, in a temporary folder, and compares each policy file with the entry's:

* every tensor bit for bit (name, dtype, shape, bytes);
* every header field but those that record when and where (``created``, wall-clock and AIP
  seconds, the curve's wall-clock, the platform record, the run flags among the
  hyper-parameters: its folder, progress bar, submitter and notes).

A difference is named where it first appears (a tensor and its first differing element, or a
header field). On another platform than the entry's, floating-point libraries may differ: the
report says both platforms beside the first difference.

The command is a result's text, so it is parsed, not run: it must be ``ials-zoo train`` with
one of our baselines, its options are read by that baseline's own parser into its arguments
(nothing is imported or run by name), and no value may name a file (``/`` or ``\\``): a result
never makes us read a path it names.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import dataclasses
import importlib
import io
import json
import math
import shlex
import subprocess
import tempfile
from pathlib import Path

import numpy as np

import ials_zoo
from ials_zoo import reference_speed
from ials_zoo.baselines import BASELINES
from ials_zoo.baselines.arguments import add_dataclass_args, dataclass_from_namespace, flag_named, hidden_sizes
from ials_zoo.core.domains import get_domain
from ials_zoo.core.extras import dials_of, study_of
from ials_zoo.errors import BadInput
from ials_zoo.evaluation import estimate_evaluation_seconds, load_model, sha256_file
from ials_zoo.leaderboard.build import hardware_info, now_iso
from ials_zoo.leaderboard.store import board_path, resolve_policy_file, training_provenance
from ials_zoo.leaderboard.validate import ResultError, load_result, validate_result
from ials_zoo.policy import HEADER_KEY
from ials_zoo.utils import atomic_write_text, format_seconds, parse_json_object, parse_untrusted_json_object

FILE_SUFFIXES = (".pt", ".pth", ".safetensors", ".npz", ".zip", ".json", ".xml", ".sumocfg", ".csv", ".txt")
"""Values that name a file: a recorded command with one is refused (it would read that file)."""

MAX_PROCESSES = 64
"""The most copies, GS processes or workers a re-trained command may ask for."""

RUN_FLAGS = ("out_dir", "resume", "overwrite", "progress", "submitter", "notes", "ray_address", "checkpoint_every")
"""Arguments that say where and how a run is watched, not what it computes: never recorded."""

MACHINE_FLAGS = ("workers", "backend")
"""How many processes a run used: the numbers do not depend on it (tests/test_exact_resume.py)."""

VOLATILE_HEADER = ("created", "training.wall_clock_seconds", "training.aip_seconds", "training.reproduce",
                   "training.reference",
                   "training.aip.collection_seconds", "training.aip.training_seconds", "package_version")
"""Header fields that record when and where a policy was trained, not what it is."""


def training_command(baseline: str, args) -> str:
    """The ``ials-zoo train`` command of a run's arguments (a baseline's ``Args``): every
    argument that differs from its default, the seed always, the run flags never."""
    parts = ["ials-zoo", "train", baseline]
    for f in dataclasses.fields(args):
        value = getattr(args, f.name)
        if f.name in RUN_FLAGS or (f.name != "seed" and f.default is not dataclasses.MISSING and value == f.default):
            continue
        flag = "--" + f.name.replace("_", "-")
        if isinstance(value, bool):
            parts.append(flag if value else "--no-" + flag[2:])
        else:
            parts += [flag, str(value)]
    return shlex.join(parts)


def package_commit() -> str | None:
    """The git commit of the installed package (``-dirty`` with local changes), or None."""
    package = Path(ials_zoo.__file__).resolve().parent

    def git(*args):
        out = subprocess.run(["git", *args], cwd=package, capture_output=True, text=True, timeout=5)
        return out.stdout.strip() if out.returncode == 0 else ""

    try:
        top = git("rev-parse", "--show-toplevel")
        if not top or Path(top).resolve() / "ials_zoo" != package:  # installed inside someone else's repository
            return None
        return git("describe", "--always", "--dirty", "--abbrev=40") or None
    except (OSError, subprocess.SubprocessError):
        return None


def platform_text() -> str:
    """What floating-point results depend on: OS, processor, Python, torch, numpy."""
    hw = hardware_info()
    return (f"{hw['platform']}; {hw['processor']}; python {hw['python']}; torch {hw['torch']}; "
            f"numpy {hw['numpy']}")[:400]


def reproduce_record(command: str) -> dict:
    """``training.reproduce`` of a result trained by ``command`` here and now."""
    return {"command": command, "package_version": ials_zoo.__version__, "commit": package_commit(),
            "platform": platform_text()}


def command_without_seed(command: str) -> list[str]:
    """The recorded command's words without its ``--seed N`` (the same for every seed)."""
    try:
        words = shlex.split(command)
    except ValueError as exc:  # an unbalanced quote: a command no shell would run either
        raise ResultError("training.reproduce.command", f"cannot be read as a command line ({exc})") from None
    out, skip = [], False
    for w in words:
        if skip:
            skip = False
        elif w == "--seed":
            skip = True
        elif not w.startswith("--seed="):
            out.append(w)
    return out


def parse_command(command: str, seed: int):
    """``(baseline module, Args)`` of a recorded command for ``seed``, checked as above."""

    words = command_without_seed(command)
    if words[:2] != ["ials-zoo", "train"] or len(words) < 3 or words[2] not in BASELINES:
        raise ResultError("training.reproduce.command", f"{command[:200]!r} is not `ials-zoo train <baseline>` with "
                          f"one of {', '.join(BASELINES)}")
    named = [w for w in words[3:] if "/" in w or "\\" in w or w.lower().endswith(FILE_SUFFIXES)]
    if named:
        raise ResultError("training.reproduce.command", f"{named[0][:100]!r} names a file; re-training runs only "
                          "commands that read no file")
    module = importlib.import_module(BASELINES[words[2]])
    parser = argparse.ArgumentParser(prog="recorded command", allow_abbrev=False, add_help=False)
    add_dataclass_args(parser, module.Args)
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            ns = parser.parse_args(words[3:] + ["--seed", str(seed)])
    except SystemExit:
        raise ResultError("training.reproduce.command", f"not a valid {words[2]} command: "
                          f"{err.getvalue().strip().splitlines()[-1][:300]}") from None
    forbidden = [k for k in RUN_FLAGS if k in vars(ns) and getattr(ns, k) != parser.get_default(k)]
    if forbidden:
        raise ResultError("training.reproduce.command", f"sets {forbidden}, which a recorded command never does")
    _check_resources(ns, words[2])
    args = dataclass_from_namespace(module.Args, ns)
    _check_values(module, args)
    return module, args


def _check_values(module, args) -> None:
    """The baseline's own checks of its arguments, on a copy (they fill in defaults): a value
    that would crash the re-train (a batch of 1, a network no policy file holds, 10**6 stacked
    frames) is refused by its flag before anything trains."""

    try:
        module.check_args(copy.deepcopy(args))
    except BadInput as exc:
        raise ResultError("training.reproduce.command", flag_named(str(exc), module.Args)) from None


def _check_matches_entry(data: dict, baseline: str, args) -> None:
    """The recorded command trains what the entry is: its baseline, domain, GS options and
    agents; otherwise a re-train would run first and fail only after."""

    where = "training.reproduce.command"
    options = parse_json_object(args.env_options, "--env-options")
    differ = [(what, mine, theirs) for what, mine, theirs in (
        ("baseline", baseline, data["algorithm"]), ("--env-id", args.env_id, data["env_id"]),
        ("--env-options", options, data["evaluation"]["options"]))
        if mine != theirs]
    domain = get_domain(data["env_id"])
    if not differ and data["track"] == "single-agent" and hasattr(args, "agent"):
        agent = args.agent or domain.default_agents[0]
        if agent != data["agent"]:
            differ.append(("--agent", agent, data["agent"]))
    if not differ and data["track"] == "multi-agent" and hasattr(args, "agents"):
        agents = domain.check_agents(None if args.agents == "all" else args.agents, **options)
        if list(agents) != list(data.get("trained_agents") or data["agents"]):
            differ.append(("--agents", f"{len(agents)} agents", f"{len(data.get('trained_agents') or data['agents'])} "
                           "agents (or others)"))
    if differ:
        what, mine, theirs = differ[0]
        raise ResultError(where, f"trains {what} {mine!r}, but the entry is of {theirs!r}: it would not re-make the "
                          "entry's policies")


def _check_resources(ns, baseline: str) -> None:
    """No process count past :data:`MAX_PROCESSES`, no Ray, and GS options of the board's kind
    only (no file paths): a recorded command asks for no more than a re-run needs."""

    where = "training.reproduce.command"
    for name in ("n_envs", "gs_processes", "workers"):
        value = getattr(ns, name, None)
        if isinstance(value, int) and value > MAX_PROCESSES:
            raise ResultError(where, f"--{name.replace('_', '-')} {value} is more than the {MAX_PROCESSES} a re-train runs")
    if getattr(ns, "backend", None) not in (None, "process"):
        raise ResultError(where, f"--backend {ns.backend!r}: a re-train runs on this machine's processes")
    try:
        options = parse_json_object(getattr(ns, "env_options", None), "--env-options")
        domain = get_domain(ns.env_id)
    except ValueError as exc:
        raise ResultError(where, str(exc)) from None
    other = sorted(set(options) - set(domain.gs_options))
    if other:
        raise ResultError(where, f"--env-options {other} are not GS options of {ns.env_id} (a re-train reads no file)")


def _header(path: Path) -> dict:
    from safetensors import safe_open

    with safe_open(str(path), framework="np") as f:
        return parse_untrusted_json_object((f.metadata() or {}).get(HEADER_KEY, "{}"), f"the header of {path}")


def _strip(header: dict) -> dict:
    """``header`` without :data:`VOLATILE_HEADER` fields and the curve's wall-clock."""
    out = json.loads(json.dumps(header))
    for dotted in VOLATILE_HEADER:
        *parents, leaf = dotted.split(".")
        node = out
        for p in parents:
            node = node.get(p) if isinstance(node, dict) else None
        if isinstance(node, dict):
            node.pop(leaf, None)
    for point in out.get("learning_curve") or []:
        if isinstance(point, dict):
            point.pop("wall_clock_seconds", None)
    training = out.get("training") if isinstance(out.get("training"), dict) else {}
    hyper = training.get("hyperparameters")
    for key in RUN_FLAGS + MACHINE_FLAGS if isinstance(hyper, dict) else ():
        hyper.pop(key, None)
    for key in MACHINE_FLAGS:
        training.pop(key, None)
    _drop_clocks(training.get("aip"))
    return out


def _drop_clocks(node) -> None:
    """Every ``*seconds*`` and ``created`` field inside ``node`` (an AIP's own records)."""
    if isinstance(node, dict):
        for key in [k for k in node if "seconds" in k or k == "created"]:
            node.pop(key)
        for value in node.values():
            _drop_clocks(value)
    elif isinstance(node, list):
        for value in node:
            _drop_clocks(value)


def _first_difference(a, b, where: str = "") -> str | None:
    """The first path at which two JSON values differ, or None."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                return f"{where}{k} (only in the {'re-trained' if k in a else 'submitted'} file)"
            found = _first_difference(a[k], b[k], f"{where}{k}.")
            if found:
                return found
        return None
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return f"{where.rstrip('.')} ({len(a)} items re-trained, {len(b)} submitted)"
        for i, (x, y) in enumerate(zip(a, b)):
            found = _first_difference(x, y, f"{where}{i}.")
            if found:
                return found
        return None
    same = a == b and type(a) is type(b)
    return None if same else f"{where.rstrip('.')} ({a!r} re-trained, {b!r} submitted)"


def policy_difference(retrained: Path, submitted: Path) -> str | None:
    """Where two policy files first differ (module docstring), or None when they are the same."""
    from safetensors.numpy import load_file

    a, b = load_file(str(retrained)), load_file(str(submitted))
    if sorted(a) != sorted(b):
        return f"tensors {sorted(a)} re-trained, {sorted(b)} submitted"
    for name in sorted(a):
        x, y = a[name], b[name]
        if x.dtype != y.dtype or x.shape != y.shape:
            return f"tensor {name}: {x.dtype}{list(x.shape)} re-trained, {y.dtype}{list(y.shape)} submitted"
        differ = np.flatnonzero(x.reshape(-1).view(np.uint8) != y.reshape(-1).view(np.uint8))
        if differ.size:
            i = int(differ[0]) // x.itemsize
            return (f"tensor {name} element {i}: {x.reshape(-1)[i]!r} re-trained, {y.reshape(-1)[i]!r} submitted "
                    f"({differ.size} differing bytes)")
    found = _first_difference(_strip(_header(retrained)), _strip(_header(submitted)))
    return None if found is None else f"header field {found}"


def _submitted_policy(data: dict, i: int, path: Path, board) -> Path:
    """Seed ``i``'s policy file as ``verify`` finds it: a relative path inside the board or next
    to the entry, with its recorded sha256, whose header agrees with the entry."""

    spec = data["scores"][i]["policy_file"]
    if Path(spec).is_absolute() or ".." in Path(spec).parts:
        raise ResultError(f"scores.{i}.policy_file", f"{spec!r}: only a path inside the board or next to the entry")
    found = resolve_policy_file(spec, path, board)
    if found is None:
        raise BadInput(f"scores.{i}: policy file {spec!r} not found")
    if sha256_file(found) != data["scores"][i]["policy_sha256"]:
        raise ResultError(f"scores.{i}.policy_sha256", f"{str(found)!r} is not the file the entry scored")
    training_provenance(dict(data, scores=[data["scores"][i]]), [load_model(found, data["agent"]).net])
    return found


UPDATE_FLOPS_PER_SECOND = 2e9
"""A generous speed of one core on a small MLP's forward and backward pass: what an estimate of
a run's PPO epochs divides by (so that it errs short, never refusing an honest run)."""


def run_parts(data: dict, args) -> list[tuple[str, float]]:
    """``(setting, seconds)``: about what each part of a re-trained run costs on 2 cores, named by
    the setting that drives it: the steps of every agent (at the slowest speed the domain's
    study measured), the PPO epochs over them, the learning-curve evaluations and the final
    evaluations (sampled and deterministic; their episodes' length included)."""

    domain = get_domain(data["env_id"])
    study = study_of(domain)
    options = parse_json_object(args.env_options, "--env-options")
    agents = len(data.get("trained_agents") or data["agents"])
    multi = hasattr(args, "hidden")
    total = float(args.total_timesteps or (study.multi_agent_budget if multi else study.budget))
    rate = max(min(list(study.multi_agent_steps_per_second.values()) + list(study.ppo_steps_per_second.values())), 1.0)
    sizes = hidden_sizes(args.hidden if multi else args.net_arch)
    weights = 2 * (sum(a * b for a, b in zip(sizes, sizes[1:])) + sizes[0] + sizes[-1])  # actor and critic, at least
    gru = int(getattr(args, "recurrent_hidden", 0) or 0)
    weights += 3 * gru * (gru + sizes[0])
    eval_every = float(args.eval_every or (max(1.0, total // 10) if multi else total))
    evaluations = math.ceil(total / eval_every) + 1
    if hasattr(args, "target_update"):  # a DQN: one minibatch update every --train-every transitions
        updates = ("--train-every/--batch-size", total / args.train_every * agents * args.batch_size * 6 * weights
                   / UPDATE_FLOPS_PER_SECOND)
    else:
        updates = ("--n-epochs" + (" and --recurrent-hidden" if gru else ""),
                   args.n_epochs * total * agents * 6 * weights / UPDATE_FLOPS_PER_SECOND)
    return [
        ("--total-timesteps", total * agents / rate),
        updates,
        (f"--eval-every/--eval-episodes ({evaluations:,} evaluations of {args.eval_episodes:,} episodes)",
         evaluations * estimate_evaluation_seconds(data["env_id"], args.eval_episodes, **options)),
        ("--final-eval-episodes", estimate_evaluation_seconds(data["env_id"], 2 * args.final_eval_episodes, **options)),
        *_aip_parts(domain, args, total, agents, rate),
    ]


def _aip_parts(domain, args, total: float, agents: int, rate: float) -> list[tuple[str, float]]:
    """DIALS's AIP rounds: each collects ``collect_steps`` GS steps of every agent and trains
    every agent's AIP ``aip_epochs`` times over them (an MLP of the domain's width, at least)."""
    from ials_zoo.baselines.aip_rounds import parse_refresh

    if not hasattr(args, "refresh"):
        return []
    settings = dials_of(domain)
    refresh = parse_refresh(args.refresh, settings.refresh)
    rounds = 0 if refresh is None else 1 + (int(total // refresh) if refresh else 0)
    steps = float(args.collect_steps or settings.collect_steps)
    epochs = float(args.aip_epochs or settings.aip_epochs)
    width = float(settings.aip_hidden)
    return [(f"--refresh/--collect-steps ({rounds:,} AIP rounds of {steps:,.0f} steps)", rounds * steps * agents / rate),
            ("--aip-epochs", rounds * epochs * steps * agents * 6 * width * width / UPDATE_FLOPS_PER_SECOND)]


def _check_cost(data: dict, jobs: list, max_seconds: float) -> None:
    """Refuse, before any training, a re-train estimated to take over ``max_seconds``: the
    entry's own training wall-clock per seed (AIP included), three times over, or what its
    command's settings make of it (:func:`run_parts`), whichever is longer; the refusal names
    the setting that costs most (an episode longer than the whole limit: its length)."""

    t = data["training"]
    claimed = 3.0 * (float(t["wall_clock_seconds"]) + float(t["aip_seconds"]))
    limit = f"over the limit of {format_seconds(max_seconds)} (--max-remeasure-hours allows more)"
    worst, seconds = "its recorded wall-clock", claimed
    for _, _, args, _ in jobs:
        options = parse_json_object(args.env_options, "--env-options")
        if estimate_evaluation_seconds(data["env_id"], 1, **options) > max_seconds:
            steps = get_domain(data["env_id"]).steps_of_episode(**options)
            raise ResultError("training.reproduce.command", f"--env-options {options}: one episode of {steps:,} steps "
                              f"would take longer than the whole re-train may, {limit}")
        parts = run_parts(data, args)
        if sum(p for _, p in parts) > seconds:
            worst, seconds = max(parts, key=lambda p: p[1])[0], sum(p for _, p in parts)
    seconds *= len(jobs)
    if seconds > max_seconds:
        raise ResultError("training", f"re-training {len(jobs)} seed(s) would take about {format_seconds(seconds)}, "
                          f"most of it from {worst}, {limit}")


def retrain(path, seeds: int = 1, directory=None, progress: bool = False,
            max_seconds: float = 4 * 3600.0) -> list[dict]:
    """Re-run the training of the first ``seeds`` training seeds of the entry at ``path``; one
    report per seed: ``seed``, ``ok`` (the policy file re-made bit for bit, as above),
    ``difference`` (where it first differs, or None), ``platform`` (this one),
    ``entry_platform``, ``commit`` (this package's) and ``entry_commit`` (the training's): code
    that changed between the two commits may change what a seed trains."""

    path = Path(path)
    data = load_result(path)
    record = (data["training"] or {}).get("reproduce")
    if data["policy"]["kind"] != "model" or record is None:
        raise ResultError("training.reproduce", "the entry records no training command (a reference entry, or "
                          "trained before commands were recorded): it can be re-scored (verify), not re-trained")
    if isinstance(seeds, bool) or not isinstance(seeds, int) or seeds < 1:
        raise BadInput(f"--seeds must be a whole number >= 1, got {seeds!r}")
    try:
        board = board_path(directory)
    except ValueError:
        board = None
    jobs = []
    for i, s in enumerate(data["scores"][:seeds]):
        if s["seed"] is None:
            raise ResultError(f"scores.{i}.seed", "a seed of null cannot be re-trained")
        module, args = parse_command(record["command"], int(s["seed"]))  # every seed checked before any runs
        _check_matches_entry(data, module.__name__.rsplit(".", 1)[1], args)
        jobs.append((s["seed"], module, args, _submitted_policy(data, i, path, board)))
    _check_cost(data, jobs, max_seconds)
    reports = []
    for seed, module, args, submitted in jobs:
        with tempfile.TemporaryDirectory(prefix="ials-zoo-retrain-") as tmp:
            args.out_dir, args.progress = str(Path(tmp) / "run"), progress
            module.main(args)
            remade = Path(args.out_dir) / "policy.safetensors"
            difference = policy_difference(remade, submitted)
            clocks = {"claimed": wall_clock_of(_header(submitted)), "retrained": wall_clock_of(_header(remade))}
        reports.append({"seed": seed, "ok": difference is None, "difference": difference,
                        "platform": platform_text(), "entry_platform": record["platform"], "wall_clock": clocks,
                        "commit": package_commit(), "entry_commit": record.get("commit")})
    return reports


def wall_clock_of(header: dict) -> dict:
    """A policy header's training wall-clock (training and AIPs, seconds) and, where the run
    measured its machine, the same in seconds of the reference machine (else None)."""
    # a submitted header is its author's text: read with care, never to crash a finished re-train
    t = header.get("training") if isinstance(header.get("training"), dict) else {}

    def number(value) -> float:
        return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else 0.0

    ref = reference_speed.of(t)
    return {"seconds": number(t.get("wall_clock_seconds")) + number(t.get("aip_seconds")),
            "reference_seconds": None if ref is None else number(ref["reference_seconds"]),
            "under_load": bool(ref) and ref.get("under_load") is True}


def wall_clock_text(clocks: dict) -> str:
    """A re-train report's line on wall-clocks: the claim's beside the re-trained run's."""
    def one(c):
        ref = "" if c["reference_seconds"] is None else f" [{format_seconds(c['reference_seconds'])} on the reference machine]"
        return format_seconds(c["seconds"]) + ref + (" (timed under load)" if c["under_load"] else "")

    claimed, retrained = clocks["claimed"], clocks["retrained"]
    text = f"wall-clock claimed {one(claimed)}, re-trained {one(retrained)}"
    if claimed["reference_seconds"] and retrained["reference_seconds"] is not None:
        text += f": {retrained['reference_seconds'] / claimed['reference_seconds']:.2f}x in reference seconds"
    elif claimed["reference_seconds"] is None:
        text += " (the claim has no reference measurement: its seconds are its machine's)"
    return text


def record_retrained(path, reports: list[dict]) -> None:
    """Write ``retrained`` into the entry at ``path`` (every report passed; atomic)."""
    if not reports or not all(r["ok"] for r in reports):
        raise BadInput("only an entry whose re-trained seeds all passed is recorded as re-trained")
    data = load_result(path)
    data["retrained"] = {"seeds": [int(r["seed"]) for r in reports], "package_version": ials_zoo.__version__,
                         "platform": platform_text(), "date": now_iso()[:10]}
    validate_result(data)  # the entry stays valid
    atomic_write_text(path, json.dumps(data, indent=2, allow_nan=False) + "\n")


__all__ = ["VOLATILE_HEADER", "wall_clock_of", "wall_clock_text", "command_without_seed", "package_commit", "parse_command", "platform_text", "run_parts",
           "policy_difference", "record_retrained", "reproduce_record", "retrain", "training_command"]
