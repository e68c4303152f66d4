"""Learning curves of the learners on RESCO's maps (docs/sumo_net.md): the GS score (mean over
lights of the episode return, RESCO's wait_norm reward) against steps per light and against
wall-clock, one line per seed, from the runs of studies/resco_maps/ippo.sh (runs/ippo_net),
idqn.sh, mplight.sh, shared_ppo.sh (runs/<learner>_net) or studies/ials_real_maps/dials.sh (runs/dials_net).
The score's axis is symmetric-log: a policy of random weights scores hundreds of times lower
than a trained one. The title names the command and the commit that drew it.

Usage: python studies/resco_maps/curves.py [runs/ippo_net] [studies/resco_maps/ippo_curves.png]
"""

import json
import subprocess
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

# a runs folder's learner and the script that fills it
SCRIPTS = {"dials": ("DIALS", "studies/ials_real_maps/dials.sh"), "idqn": ("IDQN", "studies/resco_maps/idqn.sh"),
           "mplight": ("MPLight", "studies/resco_maps/mplight.sh"),
           "shared_ppo": ("shared PPO", "studies/resco_maps/shared_ppo.sh"), "ippo": ("IPPO", "studies/resco_maps/ippo.sh")}


def main(runs="runs/ippo_net", out="studies/resco_maps/ippo_curves.png"):
    curves = {}
    for path in sorted(Path(runs).glob("*_s*/curve.json")):
        net, seed = path.parent.name.rsplit("_s", 1)
        curves.setdefault(net, []).append((int(seed), json.loads(path.read_text())["points"]))
    if not curves:
        raise SystemExit(f"no curve.json under {runs}")
    fig, axes = plt.subplots(len(curves), 2, figsize=(10, 3.2 * len(curves)), squeeze=False)
    for row, (net, runs_of_net) in zip(axes, sorted(curves.items())):
        for seed, points in sorted(runs_of_net):
            steps = [p["env_steps"] for p in points]
            wall = [p["wall_clock_seconds"] / 60 for p in points]
            mean = [p["mean"] for p in points]
            lo, hi = [p["ci_low"] for p in points], [p["ci_high"] for p in points]
            for ax, x in zip(row, (steps, wall)):
                ax.plot(x, mean, marker="o", label=f"seed {seed}")
                ax.fill_between(x, lo, hi, alpha=0.2)
                ax.set_yscale("symlog", linthresh=10)
        row[0].set(title=f"{net}: GS score vs steps per light", xlabel="steps (decisions) per light",
                   ylabel="mean return over lights")
        row[1].set(title=f"{net}: vs wall-clock", xlabel="training minutes (2 cores)")
        row[0].legend(fontsize=8)
    name = Path(runs).name.removesuffix("_net")
    learner, script = SCRIPTS.get(name, ("IPPO", "studies/resco_maps/ippo.sh"))
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    title = (f"{learner} on RESCO's maps\nbash {script}; python studies/resco_maps/curves.py {runs} {out} "
             f"(commit {commit or 'unknown'})")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(*sys.argv[1:])
