"""The array local simulator (ials_zoo.sumo_net.arrays) against SUMO regions and the GS:
fidelity (the replay contract) and cost as the number of lights grows (issue 50).

  replay   fed the GS's own entries for the map's hour, every light on its own program: the
           lights' lanes, RESCO observation and reward, per lane and step, for the SUMO regions,
           the arrays as they are and the arrays with their lane calibration; with each one's
           noise floor (two runs of its own seeds 0 and 1) -> results/replay_<net>.json
  cost     ials_zoo.sumo_net.benchmark.bench_arrays: µs per agent-decision of the GS, every
           light's IALS on SUMO regions, on arrays with 1 and with 64 copies in one batch, the
           first DECISIONS decisions of the hour, interleaved turns -> results/cost_<net>.json
  plot     results/cost_*.json as µs per agent-decision against lights, log-log -> cost.png
  table    results/cost_*.json as the Markdown table of the docs (printed)
  fidelity open loop: `ials-zoo fidelity --predictor on-policy` on each local simulator (SUMO
           regions, arrays), the same GS episodes and the same on-policy AIPs' data, under
           random lights, a fixed-time cycle (cycle:3) and any --policy-files -> results/
           fidelity_<net>.json (both reports) and fidelity_<net>.md

Each result file is written whole when its part ends; a part whose file exists is skipped
(resumable). Each names the commit it ran at.

Usage: python studies/arrays_local/run.py replay|cost|plot|table|fidelity [--nets cologne8,ingolstadt21]
       [--seconds 3600] [--decisions 120] [--repeats 3] [--episodes 10] [--policy-files A,B]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"


def commit() -> str:
    return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                          cwd=HERE).stdout.strip() or "unknown"


def _write(path: Path, data: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=1))
    tmp.replace(path)  # never half-written


def replay(net: str, seconds: int) -> dict:
    from ials_zoo.sumo_net.arrays_calibration import lane_shares
    from ials_zoo.sumo_net.regions import regions_of
    from ials_zoo.sumo_net.replay import replay_regions
    from ials_zoo.sumo_net.scenario import make_scenario

    scenario = make_scenario(net=net)
    regions = regions_of(scenario.net_file)
    out = {"net": net, "seconds": seconds, "commit": commit()}
    for name, local, calibration in (("sumo", "sumo", None), ("arrays", "arrays", None),
                                     ("arrays_calibrated", "arrays", lane_shares(scenario))):
        start = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            r = replay_regions(scenario, regions, seconds, tmp, local=local, noise_floor=True, calibration=calibration,
                               measure_cost=name == "sumo")
        out[name] = {"error": r["error"], "noise_floor": r["noise_floor"], "inserted": r["inserted"],
                     "local_seconds_per_step": r["local_seconds_per_step"], "wall_s": time.perf_counter() - start}
        out.setdefault("gs_seconds_per_step", r.get("gs_seconds_per_step"))
        print(net, name, {k: round(v, 3) for k, v in r["error"].items()}, flush=True)
    return out


def cost(net: str, decisions: int, repeats: int) -> dict:
    from ials_zoo.sumo_net.benchmark import bench_arrays, print_array_rows

    row = bench_arrays(net, repeats, decisions)
    print_array_rows([row])
    return dict(row, commit=commit(), bytes_per_copy={str(k): v for k, v in row["bytes_per_copy"].items()})


def fidelity(net: str, episodes: int, policy_files: list[str]) -> tuple[dict, str]:
    from ials_zoo.influence.fidelity import fidelity_report, markdown

    policies = ["random", "cycle:3", *policy_files]
    out, text = {"net": net, "episodes": episodes, "policies": policies, "commit": commit()}, []
    for local in ("sumo", "arrays"):
        start = time.perf_counter()
        report = fidelity_report("sumo_net_v0", policies, episodes=episodes, predictor="on-policy",
                                 ials_options={"local": local}, net=net)
        plain = json.loads(json.dumps(report, default=lambda x: x.tolist() if hasattr(x, "tolist") else str(x)))
        out[local] = dict(plain, wall_s=time.perf_counter() - start)
        text += [f"## {local}", "", markdown(report), ""]
    return out, "\n".join(text)


def plot(out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted((json.loads(p.read_text()) for p in RESULTS.glob("cost_*.json")), key=lambda r: r["agents"])
    if not rows:
        raise SystemExit(f"no cost_*.json under {RESULTS}: run `cost` first")
    fig, ax = plt.subplots(figsize=(7, 4.5))
    series = [("GS (SUMO, whole network)", "gs_us"),
              ("every light's IALS, SUMO regions", "sumo_regions_us"),
              ("IALS on arrays, 1 copy", "arrays_1_us"), ("IALS on arrays, 64 copies (per copy)", "arrays_64_us")]
    for label, key in series:
        have = [r for r in rows if r.get(key)]
        x = [r["agents"] for r in have]
        y = [r[key][0] for r in have]
        lo = [r[key][0] - r[key][1] for r in have]
        hi = [r[key][2] - r[key][0] for r in have]
        ax.errorbar(x, y, yerr=[lo, hi], marker="o", capsize=3, label=label)
    for r in rows:
        ax.annotate(r["net"], (r["agents"], r["gs_us"][0]), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.set(xscale="log", yscale="log", xlabel="lights (agents)", ylabel="µs per agent-decision")
    ax.set_title("Cost per agent-decision as the network grows\npython studies/arrays_local/run.py cost; commits "
                 + ", ".join(sorted({r["commit"] for r in rows})), fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    print(f"wrote {out}")


def _ratio(stat) -> str:
    if not stat:
        return "fails"
    digits = 3 if stat[0] < 0.3 else 2
    return f"{stat[0]:.{digits}f} [{stat[1]:.{digits}f}, {stat[2]:.{digits}f}]"


def table() -> str:
    """The cost rows as the docs show them: per network, the ratios to the GS (median [min, max]
    over the turns), the arrays' 64-copy µs, memory per copy and the commit."""
    rows = sorted((json.loads(p.read_text()) for p in RESULTS.glob("cost_*.json")), key=lambda r: r["agents"])
    lines = ["| network (lights) | GS µs per agent-decision | SUMO regions / GS | arrays, 1 copy / GS | "
             "arrays, 64 copies / GS (per copy) | arrays x64, µs | KiB per copy | commit |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['net']} ({r['agents']}) | {r['gs_us'][0]:,.0f} | {_ratio(r.get('sumo_regions_over_gs'))} | "
                     f"{_ratio(r['arrays_1_over_gs'])} | {_ratio(r['arrays_64_over_gs'])} | {r['arrays_64_us'][0]:.0f} | "
                     f"{r['bytes_per_copy']['64'] / 1024:.0f} | {r['commit']} |")
    x64 = [r["arrays_64_us"][0] for r in rows if r["agents"] >= 16]
    lines.append(f"\narrays x64 from 16 lights up: {min(x64):.1f} to {max(x64):.1f} µs, {max(x64) / min(x64):.2f}x")
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part", choices=("replay", "cost", "plot", "table", "fidelity"))
    parser.add_argument("--nets", default="cologne8,ingolstadt21")
    parser.add_argument("--seconds", type=int, default=3600)
    parser.add_argument("--decisions", type=int, default=120)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--episodes", type=int, default=10, help="fidelity: episodes per policy and simulator")
    parser.add_argument("--policy-files", default="", help="fidelity: learned joint policies, comma-separated")
    args = parser.parse_args(argv)
    if args.part == "plot":
        plot(HERE / "cost.png")
        return
    if args.part == "table":
        print(table())
        return
    for net in [x.strip() for x in args.nets.split(",") if x.strip()]:
        path = RESULTS / f"{args.part}_{net}.json"
        if path.is_file():
            print(f"done: {path}")
            continue
        if args.part == "fidelity":
            files = [x.strip() for x in args.policy_files.split(",") if x.strip()]
            data, text = fidelity(net, args.episodes, [f.replace("{net}", net) for f in files])
            (RESULTS / f"fidelity_{net}.md").write_text(f"commit {data['commit']}\n\n{text}\n")
        else:
            data = replay(net, args.seconds) if args.part == "replay" else cost(net, args.decisions, args.repeats)
        _write(path, data)


if __name__ == "__main__":
    main()
