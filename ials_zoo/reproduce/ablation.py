"""Ablation of the multi-agent PPO settings: IPPO on the GS, one setting changed at a time.

Usage::

    python -m ials_zoo.reproduce.ablation --env <domain id> --seeds 3 --budget 51200
    python -m ials_zoo.reproduce.ablation --env <domain id> --report   # the table of finished runs

Every cell is IPPO (every agent learns on the GS, :mod:`ials_zoo.baselines.ippo`) at the same
budget per agent; a cell is a base setting (``base``) with one change. The runs go into
``--out`` (``<out>/<env>/<cell>/s<seed>/``) seed by seed, every cell at seed 0 first, so a
killed ablation resumes where it stopped and a partial one is balanced across cells. Each
run's final joint policy is scored on the GS, sampled and with the most likely action
(``deterministic``), on ``--episodes`` episodes of the protocol's seeds.

The table (``<out>/<env>/ablation.md``, and ``--table`` if given) gives each cell's mean
final score over seeds with a 95% t interval, its deterministic score, the ratio to the
domain's scripted joint score and the training wall-clock.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from ials_zoo.baselines.ippo import Args
from ials_zoo.baselines.ippo import main as train_ippo
from ials_zoo.baselines.multiagent import PREVIOUS_PPO_SETTINGS
from ials_zoo.baselines.runs import DETERMINISTIC_RESULT
from ials_zoo.core.domains import get_domain
from ials_zoo.errors import BadInput
from ials_zoo.evaluation import evaluate_joint
from ials_zoo.stats import t_interval
from ials_zoo.utils import atomic_write_text, read_json_object

OLD_DEFAULTS = {k: v for k, v in PREVIOUS_PPO_SETTINGS.items() if k != "frame_stack"}
"""The multi-agent PPO settings before the ablation (SPEC §3 with the authors' buffer of 128)."""

BASE = dict(OLD_DEFAULTS, learning_rate=1e-3, anneal_lr=False, n_epochs=10, samples_per_update=512,
            batch_size=128)
"""The first candidate (the ablation's first try): lr 1e-3 held, 10 epochs of 512 samples in
minibatches of 128."""

CHANGES = {
    "old defaults": OLD_DEFAULTS,
    "base": {},
    "reward normalisation": {"normalize_reward": True},
    "lr 3e-4": {"learning_rate": 3e-4},
    "lr annealed": {"anneal_lr": True},
    "4 epochs": {"n_epochs": 4},
    "256 samples, minibatch 64": {"samples_per_update": 256, "batch_size": 64},
    "hidden 128-128": {"hidden": "128,128"},
    "entropy 0": {"ent_coef": 0.0},
    "gamma 0.95": {"gamma": 0.95},
    "no advantage normalisation": {"normalize_advantage": False},
    "frame stack 1": {"frame_stack": 1},
    "GRU 32 over the 8 frames": {"recurrent_hidden": 32},
    # round 2: the changes that helped in round 1, together
    "reward normalisation + gamma 0.95": {"normalize_reward": True, "gamma": 0.95},
    "reward normalisation + gamma 0.95 + hidden 128-128": {"normalize_reward": True, "gamma": 0.95,
                                                           "hidden": "128,128"},
    "frame stack 1 + gamma 0.95": {"frame_stack": 1, "gamma": 0.95},
    "frame stack 1 + gamma 0.95 + reward normalisation": {"frame_stack": 1, "gamma": 0.95, "normalize_reward": True},
    "frame stack 1 + gamma 0.95 + hidden 128-128": {"frame_stack": 1, "gamma": 0.95, "hidden": "128,128"},
    "GRU 32 over the 8 frames + gamma 0.95 + reward normalisation": {"recurrent_hidden": 32, "gamma": 0.95,
                                                                     "normalize_reward": True},
}
"""Cell name -> the settings it changes (``old defaults`` replaces them all)."""

ROUND_2 = [c for c in CHANGES if " + " in c]


def domain_cells(domain, round_: int = 1) -> list[str]:
    """The cells of a domain in round 1 (every single change) or round 2 (the helpful changes
    together); a policy that reads one observation only where the domain's policies read
    several (frame stack; a GRU over them)."""
    cells = [c for c in CHANGES if (c in ROUND_2) == (round_ == 2)]
    reads_frames = ("frame_stack", "recurrent_hidden")
    return [c for c in cells if domain.frame_stack > 1 or not any(k in CHANGES[c] for k in reads_frames)]


def cell_settings(env_id: str, cell: str) -> dict:
    """The IPPO settings of ``cell`` in ``env_id``."""
    if cell not in CHANGES:
        raise BadInput(f"unknown cell {cell!r}; expected one of {', '.join(CHANGES)}")
    change = CHANGES[cell]
    settings = dict(OLD_DEFAULTS) if cell == "old defaults" else dict(BASE, **change)
    # the paper's frame stack unless the cell changes it (the multi-agent default reads one now)
    settings.setdefault("frame_stack", get_domain(env_id).frame_stack)
    return settings


def _slug(cell: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in cell).strip("_")


def run_cell(env_id: str, cell: str, seed: int, budget: int, episodes: int, out: Path) -> dict:
    """Train and score one (cell, seed); returns its record (also ``record.json``)."""
    folder = out / env_id / _slug(cell) / f"s{seed}"
    record_path = folder / "record.json"
    if record_path.is_file():
        return read_json_object(record_path, what="ablation record")
    settings = cell_settings(env_id, cell)
    args = Args(env_id=env_id, seed=seed, total_timesteps=budget, eval_every=max(budget // 4, 1),
                eval_episodes=episodes, final_eval_episodes=episodes, out_dir=str(folder / "run"),
                overwrite=True, progress=False, **settings)
    result = train_ippo(args)
    det_path = folder / "run" / DETERMINISTIC_RESULT
    if det_path.is_file():
        det_mean = read_json_object(det_path, 4 << 20, what="result")["score"]["mean"]
    else:
        det_mean = evaluate_joint(env_id, str(folder / "run" / "policy.safetensors"), episodes=episodes,
                                  deterministic=True).mean
    record = {"env_id": env_id, "cell": cell, "seed": seed, "budget": budget, "settings": settings,
              "score": result["score"]["mean"], "deterministic": det_mean,
              "wall_clock_seconds": result["training"]["wall_clock_seconds"],
              "curve": [(p["env_steps"], p["mean"]) for p in result["learning_curves"][0]["points"]]}
    atomic_write_text(record_path, json.dumps(record, indent=2) + "\n")
    return record


def scripted_score(env_id: str, episodes: int, out: Path) -> float:
    """The domain's scripted joint score on the same episodes (cached in ``out``)."""

    path = out / env_id / "scripted.json"
    if path.is_file():
        cached = read_json_object(path, 4 << 20, what="scripted result")
        if cached["episodes"] == episodes:
            return float(cached["score"])
    score = evaluate_joint(env_id, "scripted", episodes=episodes).mean
    atomic_write_text(path, json.dumps({"episodes": episodes, "score": score}) + "\n")
    return score


def table(env_id: str, out: Path, scripted: float | None) -> str:
    """The Markdown table of every finished cell of ``env_id``."""
    records: dict[str, list[dict]] = {}
    for path in sorted((out / env_id).glob("*/s*/record.json")):
        rec = read_json_object(path, what="ablation record")
        records.setdefault(rec["cell"], []).append(rec)
    lines = [f"IPPO on `{env_id}`, every agent learning, one setting changed from `base` at a time "
             f"(`base`: {_describe(BASE)}). Score: mean over agents of the GS return, sampled actions; "
             f"mean over seeds [95% t interval]."
             + (f" Scripted joint score on the same episodes: {scripted:.2f}." if scripted else ""),
             "",
             "| cell | seeds | budget/agent | score | x scripted | deterministic | curve (mean over seeds) | "
             "training wall-clock |",
             "|---|---|---|---|---|---|---|---|"]
    order = [c for c in CHANGES if c in records]
    for cell in order:
        recs = sorted(records[cell], key=lambda r: r["seed"])
        scores = [r["score"] for r in recs]
        mean, lo, hi = t_interval(scores) if len(scores) > 1 else (scores[0], math.nan, math.nan)
        det = float(np.mean([r["deterministic"] for r in recs]))
        curve = np.mean([[v for _, v in r["curve"]] for r in recs], axis=0)
        ratio = f"{mean / scripted:.2f}" if scripted else "-"
        ci = f" [{lo:.2f}, {hi:.2f}]" if len(scores) > 1 else ""
        lines.append(f"| {cell} | {len(recs)} | {recs[0]['budget']:,} | {mean:.2f}{ci} | {ratio} | {det:.2f} | "
                     f"{' → '.join(f'{v:.1f}' for v in curve)} | "
                     f"{np.mean([r['wall_clock_seconds'] for r in recs]):.0f} s |")
    return "\n".join(lines) + "\n"


def _describe(settings: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in settings.items())


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ials_zoo.reproduce.ablation", description=__doc__.split("\n")[0],
                                     allow_abbrev=False)
    parser.add_argument("--env", required=True, help="domain id")
    parser.add_argument("--seeds", type=int, default=3, help="seeds per cell (0..N-1)")
    parser.add_argument("--budget", type=int, default=51_200, help="environment steps per agent")
    parser.add_argument("--episodes", type=int, default=10, help="GS episodes of each final score")
    parser.add_argument("--cells", default="all", help="comma-separated cell names, or 'all' (the domain's)")
    parser.add_argument("--round", type=int, default=1, choices=(1, 2),
                        help="1: one change at a time; 2: the helpful changes together")
    parser.add_argument("--out", default="runs/ablation", help="run folder")
    parser.add_argument("--table", default=None, help="also write the table here")
    parser.add_argument("--report", action="store_true", help="only write the table from finished runs")
    args = parser.parse_args(argv)

    domain = get_domain(args.env)
    cells = domain_cells(domain, args.round) if args.cells == "all" else args.cells.split(",")
    for cell in cells:
        cell_settings(args.env, cell)
    if args.seeds < 1 or args.budget < 1 or args.episodes < 1:
        parser.error("--seeds, --budget and --episodes must be >= 1")
    out = Path(args.out)
    if not args.report:
        start = time.perf_counter()
        for seed in range(args.seeds):
            for cell in cells:
                rec = run_cell(args.env, cell, seed, args.budget, args.episodes, out)
                print(f"ablation {args.env}: {cell} s{seed}: {rec['score']:.3f} (deterministic "
                      f"{rec['deterministic']:.3f}) [{time.perf_counter() - start:.0f} s]", flush=True)
    scripted = scripted_score(args.env, args.episodes, out)
    text = table(args.env, out, scripted)
    atomic_write_text(out / args.env / "ablation.md", text)
    if args.table:
        atomic_write_text(Path(args.table), text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
