"""``ials-zoo resco-controllers``: the rule-based controllers on RESCO's maps, beside RESCO's table.

Each episode (map, controller, seed) is one JSON file under ``--out`` (written atomically), so
a killed study resumes where it stopped by running the same command again. ``--report`` only
reads the files and prints the table: mean and median delay per map and controller, beside
RESCO's published mean and median and the ratio of the medians.

``plain_sumo`` runs the map's own program in a plain ``sumo`` process (no libsumo, no TraCI),
the same files and options: what SUMO itself gives, to tell our env's share of a gap from
SUMO's.
"""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.runtime.processes import die_with_parent
from ials_zoo.sumo.command import sumo_binary
from ials_zoo.sumo.lease import SimulationError
from ials_zoo.sumo_net import resco
from ials_zoo.sumo_net.controllers import CONTROLLERS, run_episode
from ials_zoo.sumo_net.core import episode_command
from ials_zoo.sumo_net.metrics import episode_metrics
from ials_zoo.sumo_net.scenario import RESCO_MAPS, make_scenario
from ials_zoo.utils import atomic_write_text, loads_untrusted_json, read_regular_file

ALL_CONTROLLERS = (*CONTROLLERS, "plain_sumo")
DEFAULT_MAPS = ("grid4x4", "cologne1", "cologne3", "cologne8", "ingolstadt1", "ingolstadt21")


def run_plain_sumo(seed: int, **options) -> dict[str, float]:
    """The map's own program in a plain ``sumo`` process; RESCO's metrics from its tripinfo."""
    s = make_scenario(**options)
    with tempfile.TemporaryDirectory(prefix="ials_zoo_plain_") as tmp:
        trip = os.path.join(tmp, "tripinfo.xml")
        cmd = episode_command(s.net_file, s.route_files, s.begin, s.end, seed, trip)
        cmd[0] = sumo_binary()
        start = time.perf_counter()
        done = subprocess.run(cmd, capture_output=True, timeout=3600, preexec_fn=die_with_parent)
        if done.returncode:
            raise SimulationError(f"sumo exited with {done.returncode}: {done.stderr.decode(errors='replace')[-500:]}")
        out = episode_metrics(trip, s.route_files, s.end)
        out["seconds"] = time.perf_counter() - start
        return out


def episode_file(out: Path, net: str, controller: str, seed: int) -> Path:
    return out / net / controller / f"seed_{seed}.json"


def run_one(out: Path, net: str, controller: str, seed: int) -> dict:
    """One episode, stored; an episode already stored is read back, not re-run."""
    path = episode_file(out, net, controller, seed)
    if path.exists():
        return loads_untrusted_json(read_regular_file(path, 1 << 20))
    if controller == "plain_sumo":
        metrics = run_plain_sumo(seed, net=net)
    else:
        metrics = run_episode(controller, seed, net=net)
    record = {"net": net, "controller": controller, "seed": seed, "metrics": metrics}
    atomic_write_text(path, json.dumps(record, indent=1))
    return record


def load(out: Path, net: str, controller: str, seeds=None) -> list[dict]:
    """The stored episodes of ``seeds`` (default: every one stored)."""
    folder = out / net / controller
    if not folder.is_dir():
        return []
    rows = [loads_untrusted_json(read_regular_file(p, 1 << 20)) for p in sorted(folder.glob("seed_*.json"))]
    return rows if seeds is None else [r for r in rows if r["seed"] in set(seeds)]


def _cell(values) -> str:
    return "–" if values is None else f"{values[0]:.2f} / {values[1]:.2f}"


def report(out: Path, nets, controllers, seeds=None) -> str:
    """The markdown table: ours (mean / median over the stored episodes of ``seeds``) beside RESCO's."""
    lines = ["| map | controller | episodes | delay mean / median (ours) | RESCO key: mean / median | "
             "median ours / RESCO | trip time | throughput |",
             "|---|---|---|---|---|---|---|---|"]
    for net in nets:
        for c in controllers:
            rows = load(out, net, c, seeds)
            if not rows:
                continue
            d = np.array([r["metrics"]["delay"] for r in rows])
            tt = np.mean([r["metrics"]["trip_time"] for r in rows])
            thr = np.mean([r["metrics"]["throughput"] for r in rows])
            refs = [(k, resco.RULE_BASED[net].get(k)) for k in resco.COMPARED.get(c, ())]
            ref_text = "; ".join(f"{k}: {_cell(v)}" for k, v in refs) or "–"
            ratio = "; ".join(f"{np.median(d) / v[1]:.2f}" for _, v in refs if v) or "–"
            note = f" ({resco.FILE_DIFFERENCES[net]})" if net in resco.FILE_DIFFERENCES else ""
            lines.append(f"| {net}{note} | {c} | {len(d)} | {d.mean():.2f} / {np.median(d):.2f} | {ref_text} | "
                         f"{ratio} | {tt:.1f} | {thr:.0f} |")
    return "\n".join(lines)


def configure(parser) -> None:
    parser.add_argument("--maps", default=",".join(DEFAULT_MAPS),
                        help=f"comma-separated RESCO maps (default: {','.join(DEFAULT_MAPS)})")
    parser.add_argument("--controllers", default=",".join(ALL_CONTROLLERS),
                        help=f"comma-separated, of {','.join(ALL_CONTROLLERS)} (default: all)")
    parser.add_argument("--episodes", type=int, default=30, help="episodes per map and controller (default: 30)")
    parser.add_argument("--seed-base", type=int, default=0,
                        help="SUMO seeds SEED_BASE..SEED_BASE+N-1 (default: 0; the board's protocol evaluates on "
                             "10000..10019, so --seed-base 10000 --episodes 20 scores the controllers as the board "
                             "scores policies)")
    parser.add_argument("--out", default="runs/resco_controllers", help="folder of the per-episode files (default: runs/resco_controllers)")
    parser.add_argument("--report", action="store_true", help="only print the table of what is stored")


def _names(text: str, known, flag: str) -> list[str]:
    names = [x.strip() for x in str(text).split(",") if x.strip()]
    bad = [x for x in names if x not in known]
    if not names or bad:
        raise BadInput(f"{flag}: expected names from {', '.join(known)}, got {text!r}")
    return names


def run(args) -> int:
    nets = _names(args.maps, RESCO_MAPS, "--maps")
    controllers = _names(args.controllers, ALL_CONTROLLERS, "--controllers")
    if args.episodes < 1:
        raise BadInput(f"--episodes must be >= 1, got {args.episodes}")
    if not 0 <= args.seed_base <= 2**31 - 2 - args.episodes:
        raise BadInput(f"--seed-base must be in [0, {2**31 - 2 - args.episodes}], got {args.seed_base}")
    out = Path(args.out)
    seeds = range(args.seed_base, args.seed_base + args.episodes)
    if not args.report:
        _run_all(out, nets, controllers, seeds)
    print(report(out, nets, controllers, seeds))
    return 0


def _run_all(out: Path, nets, controllers, seeds) -> None:
    jobs = [(n, c, s) for s in seeds for n in nets for c in controllers]  # seeds outer: any stop leaves even rows
    todo = [j for j in jobs if not episode_file(out, *j).exists()]
    print(f"{len(jobs)} episodes ({len(nets)} maps x {len(controllers)} controllers x {len(seeds)} seeds); "
          f"{len(jobs) - len(todo)} already stored under {out}", flush=True)
    start, done = time.perf_counter(), 0
    for net, c, seed in todo:
        record = run_one(out, net, c, seed)
        done += 1
        rate = (time.perf_counter() - start) / done
        print(f"[{done}/{len(todo)}] {net} {c} seed {seed}: delay {record['metrics']['delay']:.2f} s "
              f"({record['metrics']['seconds']:.1f} s; about {rate * (len(todo) - done) / 60:.0f} min left)", flush=True)
