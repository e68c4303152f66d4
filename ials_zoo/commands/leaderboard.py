"""``ials-zoo leaderboard``: the results board (``leaderboard/`` of the repository).

    ials-zoo leaderboard show                                   # where the board is, and its tables
    ials-zoo leaderboard submit result.json
    ials-zoo leaderboard verify leaderboard/results/<file>.json
    ials-zoo leaderboard verify --retrain [--seeds 1] [--record] leaderboard/results/<file>.json
    ials-zoo leaderboard render
    ials-zoo leaderboard merge run_s0/result.json run_s1/result.json --out merged.json
    ials-zoo leaderboard validate result.json
    ials-zoo leaderboard convert model.zip --out policy.safetensors   # SB3 zip -> policy file
    ials-zoo leaderboard export --format marl-eval --out board.json   # for marl-eval's tools
    ials-zoo leaderboard compare results/a.json results/b.json       # IQM, P(a improves on b)

The board is ``--dir``, else ``$IALS_ZOO_LEADERBOARD``, else ``./leaderboard``. See
:mod:`ials_zoo.leaderboard` and ``leaderboard/SCHEMA.md``.

Exit status: 0 done; 1 a result was read and rejected (or a verification failed); 2 bad
input: an argument, or a file that does not exist or cannot be read (as every ``ials-zoo``
command).
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from ials_zoo import leaderboard as lb
from ials_zoo.baselines.retrain import record_retrained, retrain, wall_clock_text
from ials_zoo.errors import BadInput
from ials_zoo.evaluation import load_model
from ials_zoo.leaderboard.remeasure import MAX_REMEASURE_SECONDS, mismatch_text
from ials_zoo.leaderboard.site import render_site
from ials_zoo.leaderboard.store import resolve_policy_file
from ials_zoo.policy import save_policy
from ials_zoo.utils import atomic_write_text, check_output_file


def _policies_relative_to(result: dict, source, out) -> dict:
    """``result`` (read from ``source``) with each seed's policy file, if named relative to the
    result's folder (as a training run writes it), named relative to ``out``'s folder instead."""

    there = Path(out).resolve().parent
    for s in result["scores"]:
        name = s.get("policy_file")
        found = resolve_policy_file(name, Path(source)) if name and not os.path.isabs(name) else None
        if found is not None:  # the file validation read: named so that the merged result finds it too
            s["policy_file"] = os.path.relpath(Path(found).resolve(), there)
    return result

def configure(parser):
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)

    def board(p):
        p.add_argument("--dir", default=None, help="the board folder (default: $IALS_ZOO_LEADERBOARD or ./leaderboard)")

    def cost(p):
        p.add_argument("--max-remeasure-hours", type=float, default=MAX_REMEASURE_SECONDS / 3600,
                       help="refuse, before it starts, a re-measure estimated to take longer (hours; default "
                            f"{MAX_REMEASURE_SECONDS / 3600:g})")

    p = sub.add_parser("submit", help="validate a result and add it to the board")
    p.add_argument("file")
    board(p)
    cost(p)
    p = sub.add_parser("show", help="print the board")
    p.add_argument("--sort", default="score", help="best first by 'score' (default) or a physical metric, e.g. "
                   "delay, throughput, items_per_robot (each domain knows which way is better)")
    board(p)
    p = sub.add_parser("render", help="regenerate <board>/README.md, its plots and the web page <board>/index.html")
    board(p)
    p = sub.add_parser("verify", help="re-score a result's policies on the GS (exact)")
    p.add_argument("file")
    p.add_argument("--policy", action="append", default=None,
                   help="policy file (one per training seed) when the recorded one is not found")
    p.add_argument("--retrain", action="store_true",
                   help="instead of re-scoring, re-run the entry's recorded training command and pass only if each "
                        "re-trained policy file is the submitted one, bit for bit")
    p.add_argument("--seeds", type=int, default=1, help="with --retrain: how many of its training seeds (the first)")
    p.add_argument("--record", action="store_true",
                   help="with --retrain: when every seed passes, write it into the entry (shown as re-trained)")
    board(p)
    cost(p)
    p = sub.add_parser("validate", help="check a result file without submitting it")
    p.add_argument("file")
    p = sub.add_parser("merge", help="combine single-seed results of one experiment")
    p.add_argument("files", nargs="+")
    p.add_argument("--out", required=True, help="merged result JSON (atomic)")
    p.add_argument("--notes", default=None)
    p = sub.add_parser("compare", help="IQM of two entries and the probability that the first improves on the "
                                       "second, or (--wall-clock) their wall-clocks on the reference machine")
    p.add_argument("first")
    p.add_argument("second")
    p.add_argument("--wall-clock", action="store_true",
                   help="compare the training wall-clocks in seconds of the reference machine, naming runs timed on "
                        "different machines or under load")
    p = sub.add_parser("export", help="write the board's trained entries in another tool's format")
    p.add_argument("--format", required=True, choices=["marl-eval"], help="marl-eval: InstaDeep's marl-eval JSON")
    p.add_argument("--out", default=None, help="the file to write (atomic; default: standard output)")
    board(p)
    p = sub.add_parser("convert", help="turn an SB3 PPO model zip (+ its .meta.json) into a policy file")
    p.add_argument("file")
    p.add_argument("--out", required=True, help="the .safetensors policy file to write")


def _existing_inputs(args) -> None:
    """Bad input, exit 2, before any work: a file argument that is not there."""
    files = [getattr(args, k) for k in ("file", "first", "second") if getattr(args, k, None) is not None]
    for f in files + list(getattr(args, "files", None) or []):
        if not Path(f).exists():
            raise BadInput(f"{f!r} does not exist")
    hours = getattr(args, "max_remeasure_hours", None)
    if hours is not None and not hours > 0:
        raise BadInput(f"--max-remeasure-hours must be > 0, got {hours}")


def _retrain(args) -> int:
    if args.policy:
        raise BadInput("--policy goes with a re-score, not --retrain (the entry's own policy files are compared)")
    reports = retrain(args.file, args.seeds, args.dir, progress=True, max_seconds=args.max_remeasure_hours * 3600)
    for r in reports:
        status = "OK (the policy file re-made bit for bit)" if r["ok"] else f"FAILED: first difference: {r['difference']}"
        print(f"seed {r['seed']}: re-trained: {status}\n  {wall_clock_text(r['wall_clock'])}")
    first = reports[0]
    if not all(r["ok"] for r in reports) and first["platform"] != first["entry_platform"]:
        print(f"  (trained on: {first['entry_platform']}\n   re-trained on: {first['platform']})")
    if not all(r["ok"] for r in reports) and first["commit"] != first["entry_commit"]:
        print(f"  (trained at commit {first['entry_commit']}, re-trained at commit {first['commit']}: the code "
              "between them may train otherwise)")
    ok = all(r["ok"] for r in reports)
    if ok and args.record:
        record_retrained(args.file, reports)
        print(f"recorded: {args.file} shows as re-trained")
    return 0 if ok else 1


def run(args) -> int:
    _existing_inputs(args)
    max_seconds = getattr(args, "max_remeasure_hours", 0) * 3600
    try:
        if args.action == "submit":
            print(f"accepted: {lb.submit(args.file, args.dir, max_remeasure_seconds=max_seconds)}")
        elif args.action == "validate":
            lb.load_result(args.file)
            print(f"{args.file}: valid")
        elif args.action == "merge":

            check_output_file(args.out, "--out")
            results = [_policies_relative_to(lb.load_result(f), f, args.out) for f in args.files]
            merged = lb.merge_results(results, notes=args.notes)
            lb.write_result(args.out, merged)
            s = merged["score"]
            print(f"{len(merged['scores'])} seeds: GS score {s['mean']:.3f} "
                  f"[{s['ci_low']:.3f}, {s['ci_high']:.3f}] (t-interval over seeds); wrote {args.out}")
        elif args.action == "show":
            print(lb.show(args.dir, sort=args.sort))
        elif args.action == "compare":
            compare = lb.compare_wall_clock if args.wall_clock else lb.compare_entries
            print(compare(lb.load_result(args.first), lb.load_result(args.second)))
        elif args.action == "export":
            if args.out:
                check_output_file(args.out, "--out")
            text = json.dumps(lb.export_board(args.format, args.dir), indent=1) + "\n"
            if args.out:
                atomic_write_text(args.out, text)
                print(f"wrote {args.out}")
            else:
                sys.stdout.write(text)
        elif args.action == "render":
            print(f"wrote {lb.render(args.dir)} and {render_site(args.dir)}")
        elif args.action == "convert":

            if not args.out.endswith(".safetensors"):
                raise BadInput("--out must name a .safetensors file")
            check_output_file(args.out, "--out")
            pol = load_model(args.file)
            save_policy(pol.net, args.out)
            print(f"wrote {args.out} ({pol.net!r})")
        elif args.action == "verify" and args.retrain:
            return _retrain(args)
        elif args.action == "verify":
            if args.record:
                raise BadInput("--record goes with --retrain")
            reports = lb.verify(args.file, args.policy, progress=True, directory=args.dir, max_seconds=max_seconds)
            ok = True
            for r in reports:
                status = "OK (every episode re-measured exactly)" if r["ok"] else f"FAILED ({mismatch_text(r)})"
                print(f"seed {'-' if r['seed'] is None else r['seed']}: claimed {r['claimed']:.6f}, re-measured "
                      f"{r['measured']:.6f}: {status}")
                ok &= r["ok"]
            return 0 if ok else 1
    except lb.ResultError as exc:
        print(f"ials-zoo leaderboard {args.action}: rejected: {exc}", file=sys.stderr)
        return 1
    return 0
