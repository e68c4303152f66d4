"""The rules and the learners of RESCO's maps side by side, from their result files: each map's
delay (mean [95% CI]) and its median over the 20 episodes where the result keeps each episode's
(a gridlocked episode moves the mean, not the median), and the best learned row's ratio to the
best rule's mean.

    python studies/resco_maps/table.py                   # the Markdown table
    python studies/resco_maps/table.py --copy            # first copy finished runs' results here
    python studies/resco_maps/table.py --copy --merge    # and merge each map's seeds 0-2 of a learner

Rules: ``results/rules/<map>_<rule>.json`` (``rules.sh``); learners:
``results/<learner>/<map>_s<seed>_result[_deterministic].json`` (copied from ``runs/``, :data:`LEARNERS`).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).parent / "results"
MAPS = ("cologne8", "grid4x4", "ingolstadt21", "cologne1", "ingolstadt1", "ingolstadt7", "cologne3", "arterial4x4")
RULES = ("fixed", "greedy", "max_pressure", "actuated", "random")
# learner -> its runs' folder under runs/ (idqn_wait_scaled: IDQN with --train-reward wait_scaled;
# *_wave: the lights read the wave observation, OBSERVATION=wave in learner.sh; shared_ppo_greedy_start:
# wave, --imitate greedy --train-reward queue, RUN_TAG=imitate_vf_queue; shared_ppo_queue: wave,
# --train-reward queue, RUN_TAG=queue)
LEARNERS = {"idqn": "idqn_net", "mplight": "mplight_net", "shared_ppo": "shared_ppo_net",
            "idqn_wait_scaled": "idqn_wait_scaled", "ippo": "ippo_net", "shared_ppo_anneal": "shared_ppo_anneal",
            "dials_shared": "dials_shared", "shared_ppo_wave": "shared_ppo_wave_net", "idqn_wave": "idqn_wave_net",
            "shared_ppo_drq_wave": "shared_ppo_drq_wave_net",
            "shared_ppo_greedy_start": "shared_ppo_wave_imitate_vf_queue_net",
            "shared_ppo_queue": "shared_ppo_wave_queue_net"}
SEEDS = (0, 1, 2)
SHOWN = ("idqn", "mplight", "shared_ppo", "idqn_wait_scaled", "shared_ppo_wave", "shared_ppo_drq_wave",
         "shared_ppo_greedy_start", "shared_ppo_queue")


def copy_runs(runs: Path = Path("runs")) -> None:
    """Copy each finished run's result files into ``results/<learner>/``."""
    for learner, folder in LEARNERS.items():
        for run in sorted((runs / folder).glob("*_s*")):
            for name in ("result.json", "result_deterministic.json", "curve.json", "progress.csv",
                         "agent_returns.csv"):
                if (run / "result.json").exists() and (run / name).exists():
                    (HERE / learner).mkdir(parents=True, exist_ok=True)
                    shutil.copy(run / name, HERE / learner / f"{run.name}_{name}")


def merge_seeds(runs: Path = Path("runs")) -> list[Path]:
    """``results/<learner>/<map>_merged_result[_deterministic].json`` wherever a learner's runs
    hold seeds 0-2 of a map (``ials-zoo leaderboard merge``: a t-interval over the seeds' means,
    each seed's policy file named from the merged file, so that it can be submitted)."""
    made = []
    for learner, folder in LEARNERS.items():
        for net in MAPS:
            for kind in ("", "_deterministic"):
                files = [runs / folder / f"{net}_s{s}" / f"result{kind}.json" for s in SEEDS]
                out = HERE / learner / f"{net}_merged_result{kind}.json"
                if all(f.exists() for f in files) and not out.exists():
                    subprocess.run(["ials-zoo", "leaderboard", "merge", *map(str, files), "--out", str(out)], check=True)
                    made.append(out)
    return made


def seeds_table() -> str:
    """Each learner's seeds 0-2 merged, where they are, against the best rule: whether the
    interval's upper end lies below the best rule's mean (issue 47's "beats every rule")."""
    rows = []
    for net in MAPS:
        rules = {k: r for k, r in _rules(net).items() if r}
        best = min(rules, key=lambda k: rules[k]["delay"]) if rules else None
        for learner in LEARNERS:
            pair = [row(HERE / learner / f"{net}_merged_result{kind}.json") for kind in ("", "_deterministic")]
            if pair[0] is None or best is None:
                continue
            bar = rules[best]["delay"]
            rows.append([net, learner, *(cell(r) for r in pair), f"{best} {bar:.2f}",
                         " / ".join(f"{r['delay'] / bar:.2f}" for r in pair if r),
                         " / ".join("yes" if r["hi"] < bar else "no" for r in pair if r)])
    return _markdown(["map", "learner", "seeds 0-2, sampled", "deterministic", "best rule", "learned / best rule",
                      "beats every rule"], rows)


def row(path: Path) -> dict | None:
    if not path.exists():
        return None
    m = json.loads(path.read_text())["metrics"]["delay"]
    return {"delay": m["mean"], "lo": m["ci_low"], "hi": m["ci_high"], "median": m.get("median")}


def cell(r: dict | None) -> str:
    if r is None:
        return "–"
    median = "" if r["median"] is None else f"; median {r['median']:.2f}"
    return f"{r['delay']:.2f} [{r['lo']:.2f}, {r['hi']:.2f}]{median}"


def _markdown(head: list[str], rows: list[list[str]]) -> str:
    return "\n".join(["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + ["| " + " | ".join(r) + " |"
                                                                                   for r in rows])


def _rules(net: str) -> dict:
    return {k: row(HERE / "rules" / f"{net}_{k}.json") for k in RULES}


def rules_table() -> str:
    """Every rule on every map: delay mean [95% CI]; median."""
    return _markdown(["map", *RULES], [[net, *(cell(r) for r in _rules(net).values())] for net in MAPS])


def learners_table() -> str:
    """Each learner's seed 0 (sampled / deterministic), the best rule, and the best learned
    row's ratio to it."""
    rows = []
    for net in MAPS:
        rules = {k: r for k, r in _rules(net).items() if r}
        learned = {k: (row(HERE / k / f"{net}_s0_result.json"), row(HERE / k / f"{net}_s0_result_deterministic.json"))
                   for k in SHOWN}
        best = min(rules, key=lambda k: rules[k]["delay"]) if rules else None
        best_learned = min((r["delay"] for pair in learned.values() for r in pair if r), default=None)
        ratio = f"{best_learned / rules[best]['delay']:.2f}" if best and best_learned else "–"
        beaten = [f"{k}{' (det.)' if i else ''}" for k, pair in learned.items() for i, r in enumerate(pair)
                  if r and best and r["hi"] < rules[best]["delay"]]
        cells = [f"{cell(s)} / {_det(d)}" if s and d else cell(s) for s, d in learned.values()]
        rows.append([net, *cells, f"{best} {rules[best]['delay']:.2f}" if best else "–", ratio,
                     ", ".join(beaten) or "–"])
    return _markdown(["map", *(f"{k} (sampled / deterministic)" for k in SHOWN), "best rule", "best learned / best rule",
                      "beats every rule (upper end below the best rule's mean)"], rows)


def _det(r: dict) -> str:
    return f"{r['delay']:.2f} [{r['lo']:.2f}, {r['hi']:.2f}]"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--copy", action="store_true", help="copy finished runs' result files from runs/ first")
    p.add_argument("--merge", action="store_true", help="merge each learner's seeds 0-2 of a map (where all are)")
    args = p.parse_args(argv)
    if args.copy:
        copy_runs()
    if args.merge:
        for path in merge_seeds():
            print(f"merged: {path}", file=sys.stderr)
    print(rules_table() + "\n\n" + learners_table() + "\n\n" + seeds_table())
    return 0


if __name__ == "__main__":
    sys.exit(main())
