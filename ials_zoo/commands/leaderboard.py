"""``ials-zoo leaderboard``: the results board (``leaderboard/`` of the repository).

    ials-zoo leaderboard show                                   # where the board is, and its tables
    ials-zoo leaderboard submit result.json
    ials-zoo leaderboard verify leaderboard/results/<file>.json
    ials-zoo leaderboard render
    ials-zoo leaderboard merge run_s0/result.json run_s1/result.json --out merged.json
    ials-zoo leaderboard validate result.json
    ials-zoo leaderboard convert model.zip --out policy.safetensors   # SB3 zip -> policy file
    ials-zoo leaderboard export --format marl-eval --out board.json   # for marl-eval's tools
    ials-zoo leaderboard compare results/a.json results/b.json       # IQM, P(a improves on b)

The board is ``--dir``, else ``$IALS_ZOO_LEADERBOARD``, else ``./leaderboard``. See
:mod:`ials_zoo.leaderboard` and ``leaderboard/SCHEMA.md``. A rejected submission or a failed
verification exits with status 1, bad input with 2.
"""

from __future__ import annotations

import sys

from ials_zoo import leaderboard as lb
from ials_zoo.errors import BadInput
from ials_zoo.evaluation import load_model
from ials_zoo.policy import save_policy
from ials_zoo.utils import atomic_write_text, check_output_file


def configure(parser):
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)

    def board(p):
        p.add_argument("--dir", default=None, help="the board folder (default: $IALS_ZOO_LEADERBOARD or ./leaderboard)")

    p = sub.add_parser("submit", help="validate a result and add it to the board")
    p.add_argument("file")
    board(p)
    p = sub.add_parser("show", help="print the board")
    p.add_argument("--sort", default="score", help="best first by 'score' (default) or a physical metric, e.g. "
                   "delay, throughput, items_per_robot (each domain knows which way is better)")
    board(p)
    p = sub.add_parser("render", help="regenerate <board>/README.md and its plots")
    board(p)
    p = sub.add_parser("verify", help="re-score a result's policies on the GS (exact)")
    p.add_argument("file")
    p.add_argument("--policy", action="append", default=None,
                   help="policy file (one per training seed) when the recorded one is not found")
    board(p)
    p = sub.add_parser("validate", help="check a result file without submitting it")
    p.add_argument("file")
    p = sub.add_parser("merge", help="combine single-seed results of one experiment")
    p.add_argument("files", nargs="+")
    p.add_argument("--out", required=True, help="merged result JSON (atomic)")
    p.add_argument("--notes", default=None)
    p = sub.add_parser("compare", help="IQM of two entries and the probability that the first improves on the second")
    p.add_argument("first")
    p.add_argument("second")
    p = sub.add_parser("export", help="write the board's trained entries in another tool's format")
    p.add_argument("--format", required=True, choices=["marl-eval"], help="marl-eval: InstaDeep's marl-eval JSON")
    p.add_argument("--out", default=None, help="the file to write (atomic; default: standard output)")
    board(p)
    p = sub.add_parser("convert", help="turn an SB3 PPO model zip (+ its .meta.json) into a policy file")
    p.add_argument("file")
    p.add_argument("--out", required=True, help="the .safetensors policy file to write")


def run(args) -> int:

    try:
        if args.action == "submit":
            print(f"accepted: {lb.submit(args.file, args.dir)}")
        elif args.action == "validate":
            lb.load_result(args.file)
            print(f"{args.file}: valid")
        elif args.action == "merge":

            check_output_file(args.out, "--out")
            merged = lb.merge_results([lb.load_result(f) for f in args.files], notes=args.notes)
            lb.write_result(args.out, merged)
            s = merged["score"]
            print(f"{len(merged['scores'])} seeds: GS score {s['mean']:.3f} "
                  f"[{s['ci_low']:.3f}, {s['ci_high']:.3f}] (t-interval over seeds); wrote {args.out}")
        elif args.action == "show":
            print(lb.show(args.dir, sort=args.sort))
        elif args.action == "compare":
            print(lb.compare_entries(lb.load_result(args.first), lb.load_result(args.second)))
        elif args.action == "export":
            import json


            if args.out:
                check_output_file(args.out, "--out")
            text = json.dumps(lb.export_board(args.format, args.dir), indent=1) + "\n"
            if args.out:
                atomic_write_text(args.out, text)
                print(f"wrote {args.out}")
            else:
                sys.stdout.write(text)
        elif args.action == "render":
            print(f"wrote {lb.render(args.dir)}")
        elif args.action == "convert":

            if not args.out.endswith(".safetensors"):
                raise BadInput("--out must name a .safetensors file")
            check_output_file(args.out, "--out")
            pol = load_model(args.file)
            save_policy(pol.net, args.out)
            print(f"wrote {args.out} ({pol.net!r})")
        elif args.action == "verify":
            reports = lb.verify(args.file, args.policy, progress=True, directory=args.dir)
            ok = True
            for r in reports:
                status = "OK (every episode re-measured exactly)" if r["ok"] else f"FAILED (episodes differ: {r['differences'][:10]})"
                print(f"seed {'-' if r['seed'] is None else r['seed']}: claimed {r['claimed']:.6f}, re-measured "
                      f"{r['measured']:.6f}: {status}")
                ok &= r["ok"]
            return 0 if ok else 1
    except lb.ResultError as exc:
        print(f"ials-zoo leaderboard {args.action}: rejected: {exc}", file=sys.stderr)
        return 1
    return 0
