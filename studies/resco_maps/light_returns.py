"""Which light's return moves when a run's mean return does: a run's ``agent_returns.csv`` (each
light's own mean training-episode return per stretch), its best stretch against its last ones.

    python studies/resco_maps/light_returns.py runs/shared_ppo_anneal/ingolstadt21_s0 [--plot F.png]

For each light: its return at the run's best stretch (the highest mean over lights, after the
first fifth of the budget), its mean over the last fifth, and its share of the fall of the sum
from one to the other. Returns are RESCO's ``wait_norm`` sums per episode, so a light whose
reward sits at the clip (-4 per decision) falls to about -1,440 per 360-decision episode.
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
from pathlib import Path

import numpy as np


def read(folder: Path) -> tuple[np.ndarray, list[str], np.ndarray]:
    """Steps per light, the lights, and returns ``[stretch, light]`` (NaN where none ended)."""
    path = Path(folder) / "agent_returns.csv"
    if not path.is_file():
        raise SystemExit(f"{path}: no such file (runs of several agents write it since commit 170431e)")
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    lights = rows[0][1:]
    steps = np.array([float(r[0]) for r in rows[1:]])
    returns = np.array([[float(v) if v else np.nan for v in r[1:]] for r in rows[1:]])
    return steps, lights, returns


def fall(steps: np.ndarray, returns: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """The best stretch (after the first fifth), each light's return there, and its mean over the
    last fifth."""
    mean = np.nanmean(returns, axis=1)
    late = steps >= 0.8 * steps[-1]
    eligible = np.where(steps > 0.2 * steps[-1], mean, -np.inf)
    best = int(np.argmax(eligible))
    return best, returns[best], np.nanmean(returns[late], axis=0)


def report(folder: Path) -> None:
    steps, lights, returns = read(folder)
    best, at_best, last = fall(steps, returns)
    drop = at_best - last
    total = np.nansum(drop)
    print(f"{folder}: mean return {np.nanmean(at_best):.1f} at its best stretch ({steps[best]:,.0f} steps per light), "
          f"{np.nanmean(last):.1f} over the last fifth; the sum falls by {total:.0f}")
    for i in np.argsort(-drop):
        share = drop[i] / total if total > 0 else float("nan")
        print(f"  {lights[i][:34]:34s} {at_best[i]:9.1f} -> {last[i]:9.1f}  ({share:+.0%} of the fall)")


def plot(folder: Path, out: Path, top: int = 4) -> None:
    """Each light's return against steps: the ``top`` lights of the largest fall named."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps, lights, returns = read(folder)
    _, at_best, last = fall(steps, returns)
    named = set(np.argsort(-(at_best - last))[:top])
    fig, ax = plt.subplots(figsize=(8, 4.5))
    colours = iter(["tab:red", "tab:blue", "tab:orange", "tab:green", "tab:purple"])
    for i, light in enumerate(lights):
        if i in named:
            ax.plot(steps, returns[:, i], lw=2, color=next(colours), label=light[:24])
        else:
            ax.plot(steps, returns[:, i], lw=0.8, color="grey", alpha=0.4)
    ax.set_xlabel("steps per light")
    ax.set_ylabel("training-episode return (wait_norm)")
    ax.set_title(f"{Path(folder).parent.name}/{Path(folder).name}: each light's return (named: the largest falls)",
                 fontsize=10)
    ax.legend(fontsize=8)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    fig.text(0.01, 0.01, f"python studies/resco_maps/light_returns.py {folder} --plot {out} (commit {commit or '?'})",
             fontsize=7)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    fig.savefig(out, dpi=110)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", nargs="+", type=Path)
    p.add_argument("--plot", type=Path, help="draw the first run's lights to this PNG")
    args = p.parse_args(argv)
    for folder in args.runs:
        report(folder)
    if args.plot:
        plot(args.runs[0], args.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
