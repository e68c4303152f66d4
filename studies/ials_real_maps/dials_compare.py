"""DIALS variants beside IPPO on one map: the GS score (mean over lights of the episode return)
at each evaluation, against steps per light and against wall-clock (AIP rounds included), one
line per run folder.

Usage: python studies/ials_real_maps/dials_compare.py OUT.png LABEL=RUN_FOLDER [LABEL=RUN_FOLDER ...]

    python studies/ials_real_maps/dials_compare.py studies/ials_real_maps/dials_exits.png \\
        "IPPO s0=runs/ippo_net/ingolstadt21_s0" "IPPO s1=runs/ippo_net/ingolstadt21_s1" \\
        "IPPO s2=runs/ippo_net/ingolstadt21_s2" "DIALS, entries (e3f4e38)=runs/dials_net/ingolstadt21_s0" \\
        "DIALS, exits per second (89aae0a)=runs/dials_exits/ingolstadt21_s0" \\
        "DIALS, exits per decision (6c4cdf8)=runs/dials_exits2/ingolstadt21_s0"
"""

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def main(out: str, *runs: str) -> None:
    if not runs or any("=" not in r for r in runs):
        raise SystemExit(__doc__)
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    for spec in runs:
        label, _, folder = spec.partition("=")
        path = Path(folder) / "curve.json"
        if not path.is_file():
            raise SystemExit(f"{label}: no {path}")
        points = json.loads(path.read_text())["points"]
        mean = [p["mean"] for p in points]
        for ax, x in zip(axes, ([p["env_steps"] for p in points], [p["wall_clock_seconds"] / 60 for p in points])):
            ax.plot(x, mean, marker="o", label=label, linestyle="--" if label.startswith("IPPO") else "-")
    axes[0].set(title="GS score vs steps per light", xlabel="steps (decisions) per light",
                ylabel="mean return over lights (one evaluation)")
    axes[1].set(title="vs wall-clock (2 cores, other jobs beside)", xlabel="training minutes")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(*sys.argv[1:])
