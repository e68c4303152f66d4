"""The board in other tools' formats.

``marl-eval`` (InstaDeep's ``id-marl-eval``, Gorsane et al. 2022) reads one JSON object::

    {env: {task: {algorithm: {"run_<seed>": {"step_<i>": {"step_count": int,
                                                           "episode_return": [float, ...]},
                                             ...,
                                             "absolute_metrics": {"episode_return": [float, ...]}}}}}}

Here ``env`` is the domain's id (``traffic_grid_v0``), ``task`` the agents evaluated (an agent's
name on the single-agent track, ``"<n>-agents"`` on the multi-agent one, after the domain's
track options: ``net=cologne8/8-agents``), ``algorithm`` the
entry's algorithm and training simulator (``dials/dials-once``, ``ippo/gs``; a sampled entry
and a ``deterministic`` one are two algorithms; where one task holds several entries of one
algorithm, each is its own, its entry id after it: ``shared_ppo/gs/346c743eda24``),
``run_<seed>`` one training seed. A step
is one point of that seed's learning curve: its ``episode_return`` holds the curve point's mean
(the board keeps a curve's means, not its episodes). ``absolute_metrics`` holds the final
evaluation's returns, one per episode of the protocol, and the entry's physical ``metrics``
where it has them (their means, one value per seed). Only the board's official-protocol entries
are exported; references (scripted, random) have no training run and are left out.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from ials_zoo import reference_speed
from ials_zoo.core.domains import get_domain
from ials_zoo.errors import BadInput
from ials_zoo.leaderboard.render import console_text, format_duration
from ials_zoo.leaderboard.store import load_entries
from ials_zoo.stats import iqm_interval, probability_of_improvement


def algorithm_label(data: dict) -> str:
    """``algorithm/simulator``, with ``/deterministic`` for a deterministic evaluation."""
    label = f"{data['algorithm']}/{(data.get('training') or {}).get('simulator') or 'none'}"
    if data.get("evaluation", {}).get("deterministic"):
        label += "/deterministic"
    return label


def task_label(data: dict) -> str:
    """The agents evaluated, after the domain's track options where it has any (one task per
    network: ``net=cologne8/8-agents``)."""
    label = f"{len(data['agents'])}-agents" if data.get("track") == "multi-agent" else str(data["agent"])
    tracked = [f"{k}={v}" for k, v in sorted(data["evaluation"]["options"].items())
               if k in get_domain(data["env_id"]).track_options]
    return "/".join([*tracked, label])


def marl_eval(entries) -> dict:
    """The marl-eval JSON object of ``entries`` (``(path, data)`` pairs; module docstring)."""
    out: dict = {}
    chosen = [(path, data) for path, data in entries if data.get("evaluation", {}).get("protocol") == "official"
              and data.get("policy", {}).get("kind") == "model"]
    keys = Counter((d["env_id"], task_label(d), algorithm_label(d)) for _, d in chosen)
    for path, data in chosen:
        algorithm = algorithm_label(data)
        if keys[(data["env_id"], task_label(data), algorithm)] > 1:  # its seeds would overwrite another's
            algorithm += "/" + Path(path).stem.rsplit("__", 1)[-1]
        curves = {c["seed"]: c["points"] for c in data.get("learning_curves") or []}
        runs = out.setdefault(data["env_id"], {}).setdefault(task_label(data), {}).setdefault(algorithm, {})
        for score in data["scores"]:
            seed = score["seed"]
            run: dict = {}
            for i, point in enumerate(curves.get(seed, [])):
                run[f"step_{i}"] = {"step_count": int(point["env_steps"]), "episode_return": [float(point["mean"])]}
            absolute = {"episode_return": [float(r) for r in score["returns"]]}
            for name, value in (score.get("metrics") or {}).items():
                absolute[name] = [float(value["mean"])]
            run["absolute_metrics"] = absolute
            runs[f"run_{seed}"] = run
    return out


def compare_entries(first: dict, second: dict) -> str:
    """Two entries of one domain and agents, the way the field compares them: each one's IQM
    over its training seeds with a bootstrap interval, and the probability of improvement
    P(a seed of the first scores above a seed of the second), with its interval."""
    for field in ("env_id", "agents"):
        if first[field] != second[field]:
            raise BadInput(f"the entries differ in {field}: {first[field]!r} vs {second[field]!r}")
    for name, d in (("first", first), ("second", second)):
        if d["training"] is None:
            raise BadInput(f"the {name} entry is a reference entry ({d['algorithm']}): compare needs two trained "
                           "entries, each with at least 2 training seeds (their spread is what is compared)")
        if len(d["scores"]) < 2:
            raise BadInput(f"the {name} entry has {len(d['scores'])} training seed: compare needs at least 2 per "
                           "entry (merge single-seed results with `ials-zoo leaderboard merge`)")
    lines = []
    seeds = []
    for name, d in (("first", first), ("second", second)):
        scores = [s["mean"] for s in d["scores"]]
        seeds.append(scores)
        iqm, lo, hi = iqm_interval([scores])
        mode = "deterministic" if d["evaluation"].get("deterministic") else "sampled"
        lines.append(f"{name}: {algorithm_label(d)} ({mode}), {len(scores)} seed{'s' if len(scores) != 1 else ''}: "
                     f"IQM {iqm:.3f} [{lo:.3f}, {hi:.3f}]")
    p, lo, hi = probability_of_improvement(*seeds)
    lines.append(f"P(first > second) = {p:.3f} [{lo:.3f}, {hi:.3f}] (95% bootstrap over seeds)")
    return "\n".join(lines)


def compare_wall_clock(first: dict, second: dict) -> str:
    """Two trained entries' wall-clocks, in seconds and in seconds of the reference machine
    (:mod:`ials_zoo.reference_speed`), and their ratio in the figure that can be compared: the
    reference seconds where both measured their machine, else the seconds, said so. It names
    runs timed on different machines and runs timed under load."""
    lines, refs, totals = [], [], []
    for name, d in (("first", first), ("second", second)):
        t = d["training"]
        if t is None:
            raise BadInput(console_text(f"the {name} entry is a reference entry ({d['algorithm']}): it has no training "
                                        "wall-clock"))
        total = float(t["wall_clock_seconds"]) + float(t["aip_seconds"])
        ref = reference_speed.of(t)
        totals.append(total)
        refs.append(ref)
        where = ("no reference measurement (trained before runs measured their machine)" if ref is None else
                 f"{format_duration(ref['reference_seconds'])} on the reference machine; timed on "
                 f"{ref['machine']}" + (", under load (its speed moved by more than 20%)" if ref["under_load"] else ""))
        lines.append(console_text(f"{name}: {algorithm_label(d)} on {d['env_id']}, {len(d['scores'])} seed(s): "
                                  f"{format_duration(total)} of wall-clock (training + AIPs); {where}"))
    if all(refs):
        ratio = refs[0]["reference_seconds"] / max(refs[1]["reference_seconds"], 1e-9)
        lines.append(f"first / second = {ratio:.2f} in reference seconds ({totals[0] / max(totals[1], 1e-9):.2f} "
                     "in seconds)")
        if refs[0]["machine"] != refs[1]["machine"]:
            lines.append("timed on different machines: compare the reference seconds, not the seconds")
    else:
        lines.append(f"first / second = {totals[0] / max(totals[1], 1e-9):.2f} in seconds only: not both runs "
                     "measured their machine, so machines and loads may differ 2-4x")
    loaded = [n for n, r in zip(("first", "second"), refs) if r is not None and r["under_load"]]
    if loaded:
        lines.append(f"timed under load: {' and '.join(loaded)}; its seconds are not a quiet machine's (the "
                     "reference seconds correct for a steady load, not for one that came and went)")
    return "\n".join(lines)


def export_board(fmt: str, directory=None) -> dict:
    """The board of ``directory`` in format ``fmt`` (only ``"marl-eval"``)."""
    if fmt != "marl-eval":
        raise BadInput(f"unknown export format {fmt!r}; expected 'marl-eval'")
    entries, _bad = load_entries(directory)
    return marl_eval(entries)


__all__ = ["algorithm_label", "compare_entries", "export_board", "marl_eval", "task_label"]
