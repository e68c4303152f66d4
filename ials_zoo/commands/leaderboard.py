"""``ials-zoo leaderboard {submit,show,render,verify}``: the results board in ``leaderboard/``.

    ials-zoo leaderboard submit result.json [--dir leaderboard]
    ials-zoo leaderboard merge run_s0/result.json run_s1/result.json --out merged.json
    ials-zoo leaderboard show
    ials-zoo leaderboard render
    ials-zoo leaderboard verify leaderboard/results/<file>.json [--policy model.zip]

See :mod:`ials_zoo.leaderboard` and ``leaderboard/SCHEMA.md``.
"""

from __future__ import annotations

import sys


def configure(parser):
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    p = sub.add_parser("submit", help="validate a result and add it to the board")
    p.add_argument("file")
    p.add_argument("--dir", default="leaderboard", help="leaderboard folder")
    p = sub.add_parser("show", help="print the board")
    p.add_argument("--dir", default="leaderboard", help="leaderboard folder")
    p = sub.add_parser("render", help="regenerate <dir>/README.md and its plots")
    p.add_argument("--dir", default="leaderboard", help="leaderboard folder")
    p = sub.add_parser("verify", help="re-score a result's policy on the GS")
    p.add_argument("file")
    p.add_argument("--policy", action="append", default=None,
                   help="policy file (one per training seed) when the recorded path is not valid here")
    p = sub.add_parser("validate", help="check a result file without submitting it")
    p.add_argument("file")
    p = sub.add_parser("merge", help="combine single-seed results of one experiment")
    p.add_argument("files", nargs="+")
    p.add_argument("--out", required=True, help="merged result JSON (atomic)")
    p.add_argument("--notes", default=None)


def run(args) -> int:
    from ials_zoo import leaderboard as lb

    try:
        if args.action == "submit":
            dest = lb.submit(args.file, args.dir)
            print(f"accepted: {dest}")
        elif args.action == "validate":
            lb.load_result(args.file)
            print(f"{args.file}: valid")
        elif args.action == "merge":
            merged = lb.merge_results([lb.load_result(f) for f in args.files], notes=args.notes)
            lb.write_result(args.out, merged)
            s = merged["score"]
            print(f"{len(merged['scores'])} seeds: GS score {s['mean']:.3f} "
                  f"[{s['ci_low']:.3f}, {s['ci_high']:.3f}] (t-interval over seeds); wrote {args.out}")
        elif args.action == "show":
            print(lb.show(args.dir))
        elif args.action == "render":
            print(f"wrote {lb.render(args.dir)}")
        elif args.action == "verify":
            reports = lb.verify(args.file, args.policy, progress=True)
            ok = True
            for r in reports:
                status = "OK" if r["ok"] else "FAILED"
                print(f"seed {'-' if r['seed'] is None else r['seed']}: claimed {r['claimed']:.4f}, re-measured "
                      f"{r['measured']:.4f} [{r['ci'][0]:.4f}, {r['ci'][1]:.4f}] "
                      f"{'(exact)' if r['exact'] else ''} {status}")
                ok &= r["ok"]
            return 0 if ok else 1
    except lb.ResultError as exc:
        print(f"rejected: {exc}", file=sys.stderr)
        return 1
    except (ValueError, TypeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0
