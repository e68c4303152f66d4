"""``ials-zoo bench``: how fast the simulators are, measured in one run on this machine.

Default: for each domain, in one process, repeated ``--repeats`` times (interleaved, so a
noisy neighbour hits every measurement alike) and reported as median [min, max]:

* **single agent** (the paper's setting: one learner, its neighbours scripted): GS steps/s,
  IALS steps/s (one local simulator + one AIP call per step) and the batched IALS
  (``--batch`` copies of one agent's IALS per step), with the IALS/GS speed ratios;
* **every agent learning** (DIALS's setting), in microseconds per agent-step: the GS with every
  agent acting; the multi-agent IALS as a PettingZoo ``ParallelEnv`` (one copy per agent, dict
  in, dicts out); and as DIALS trains on it (every agent's region x the domain's copies per
  agent, arrays in and out); with each one's cost relative to the GS's (< 1: cheaper);
* **the learner** (what IPPO and DIALS add per agent-step): the batched PPO's action
  selection per agent-step and its update per agent-sample, at the multi-agent settings.

The IALS uses ``--predictor`` (default ``trained``: the shipped AIPs; the multi-agent IALS uses
the shipped set of every agent). The machine (CPU, cores, versions) heads the output and the
``--out`` JSON. ``--ppo`` and ``--scaling`` are other measurements (see their help).

Wall-clock numbers depend on whatever else the machine does: run it on an idle machine and
compare ratios taken in one run rather than absolute figures from different runs.
"""


from __future__ import annotations

import json
import os

from ials_zoo.bench.measure import bench_aip_archs, bench_domain, bench_ppo, bench_scaling, bench_versus, machine_info
from ials_zoo.bench.report import plot_scaling, print_domain, verdict
from ials_zoo.commands import CommandError
from ials_zoo.core.domains import domain_ids, get_domain, ials_domain_ids
from ials_zoo.core.extras import bench_of
from ials_zoo.utils import atomic_write_text


def configure(parser):
    parser.add_argument("--domain", choices=["all", *domain_ids()], default="all",
                        help="'all' (the default): every domain whose agents share their spaces ("
                             + ", ".join(ials_domain_ids()) + "), one after the other; a domain whose agents each "
                             "have their own (a network's lights: sumo_net_v0) has a benchmark of its own, "
                             "--domain NAME [--net M,...]")
    parser.add_argument("--steps", type=int, default=None,
                        help="GS steps per measurement (default: 10 episodes)")
    parser.add_argument("--repeats", type=int, default=5, help="repeats of every measurement (median, min, max)")
    parser.add_argument("--batch", type=int, default=64,
                        help="copies in the batched single-agent IALS measurement")
    parser.add_argument("--predictor", default="trained",
                        help="AIP used by the IALS (trained, untrained, uniform, fixed:P, a file)")
    parser.add_argument("--scaling", action="store_true",
                        help="instead: GS vs IALS cost as the system grows, with a plot")
    parser.add_argument("--ppo", action="store_true",
                        help="instead: time PPO training on the GS, the IALS and no simulator (PPO's own cost)")
    parser.add_argument("--ppo-steps", type=int, default=30_000, help="PPO steps per --ppo measurement")
    parser.add_argument("--versus", default=None, metavar="AIP_SET",
                        help="instead: the multi-agent IALS (ParallelEnv and DIALS's batched core) with the "
                             "--predictor AIPs against this AIP set file (e.g. autoregressive ones), beside the GS")
    parser.add_argument("--aip-archs", default=None, metavar="ARCH-HIDDEN[-ar],...",
                        help="instead: the multi-agent IALS ParallelEnv with every agent's AIP of each of these "
                             "architectures, e.g. gru-64-ar,gru-32-ar,mlp-128, beside the GS (untrained weights: the "
                             "network's cost is a trained one's, but a local simulator whose cost follows the "
                             "influence, SUMO's inserted vehicles, runs at untrained arrival rates)")
    parser.add_argument("--net", default=None, metavar="NAME[,NAME]",
                        help="a domain with a GS only and several networks: the networks to measure, its GS against raw "
                             "SUMO (default: the domain's)")
    parser.add_argument("--out", default=None, help="write the figures (and the machine) as JSON here")
    parser.add_argument("--plot", default="bench_scaling.png",
                        help="PNG for --scaling (default: bench_scaling.png)")
    parser.add_argument("--seed", type=int, default=0)



def parse_aip_archs(text: str) -> list[tuple[str, int, bool]]:
    """``"gru-64-ar,mlp-128"`` -> ``[("gru", 64, True), ("mlp", 128, False)]``."""
    archs = []
    for item in str(text).split(","):
        parts = item.strip().split("-")
        if (len(parts) not in (2, 3) or parts[0] not in ("gru", "mlp") or not parts[1].isdigit()
                or int(parts[1]) < 1 or (len(parts) == 3 and parts[2] != "ar")):
            raise CommandError(f"--aip-archs {item.strip()!r}: expected ARCH-HIDDEN[-ar] with ARCH gru or mlp, "
                               "e.g. gru-64-ar or mlp-128")
        archs.append((parts[0], int(parts[1]), len(parts) == 3))
    return archs


def run(args) -> int:

    if args.steps is not None and args.steps < 1:
        raise CommandError(f"--steps must be >= 1, got {args.steps}")
    if args.batch < 1:
        raise CommandError(f"--batch must be >= 1, got {args.batch}")
    if args.repeats < 1:
        raise CommandError(f"--repeats must be >= 1, got {args.repeats}")
    if args.ppo and args.ppo_steps < 1:
        raise CommandError(f"--ppo-steps must be >= 1, got {args.ppo_steps}")
    archs = parse_aip_archs(args.aip_archs) if args.aip_archs else None
    env_ids = ials_domain_ids() if args.domain == "all" else [args.domain]
    domains = [get_domain(env_id) for env_id in env_ids]  # resolved once, here
    gs_only = args.domain != "all" and not domains[0].has_ials
    if gs_only and bench_of(args.domain).gs_runner is None:
        raise CommandError(f"--domain {args.domain} has no IALS and no benchmark of its GS")
    if args.net is not None and not gs_only:
        raise CommandError("--net is for a domain with a GS only (--domain one of "
                           f"{', '.join(d for d in domain_ids() if not get_domain(d).has_ials) or 'none'})")
    ials_flags = [f for f, on in (("--ppo", args.ppo), ("--scaling", args.scaling), ("--versus", args.versus),
                                  ("--aip-archs", args.aip_archs), ("--steps", args.steps is not None)) if on]
    if gs_only and ials_flags:
        raise CommandError(f"{', '.join(ials_flags)}: --domain {args.domain} has no IALS to measure; "
                           "its benchmark takes --net and --repeats")
    nets = None if args.net is None else [x.strip() for x in args.net.split(",") if x.strip()]
    known = bench_of(args.domain).nets if gs_only else ()
    if nets is not None and known and not set(nets) <= set(known):
        raise CommandError(f"--net: unknown map(s) {sorted(set(nets) - set(known))}; expected some of {', '.join(known)}")
    machine = machine_info()
    print(f"machine: {machine['cpu']}, {machine['cores']} cores; python {machine['python']}, torch {machine['torch']}, "
          f"numpy {machine['numpy']}, SUMO {machine['sumo']}, ials_zoo {machine['ials_zoo']}", flush=True)
    if gs_only:
        rows = bench_of(args.domain).gs_runner(nets, args.repeats)
    elif args.ppo:
        rows = [r for domain in domains for r in bench_ppo(domain, args.ppo_steps, args.predictor, args.seed)]
        print(f"\nppo_single training throughput ({args.ppo_steps} steps each, 8 envs, evaluation excluded)")
        print(f"{'domain':<16}{'simulator':<12}{'PPO steps/s':>12}{'time/step vs GS':>17}")
        for r in rows:
            print(f"{r['domain']:<16}{r['simulator']:<12}{r['steps_per_s']:>12,.0f}{r['time_per_step_vs_gs']:>17.2f}")
        print("'none' is PPO alone (a simulator that costs nothing): no IALS can train in less than that "
              "share of the GS's wall-clock.")
    elif archs:
        rows = [bench_aip_archs(domain, args.steps, archs, args.seed, args.repeats) for domain in domains]
    elif args.versus:
        if not os.path.isfile(args.versus):
            raise CommandError(f"--versus {args.versus!r}: no such AIP set file")
        rows = [bench_versus(domain, args.steps, args.predictor, args.versus, args.seed, args.repeats)
                for domain in domains]
    elif args.scaling:
        rows = [r for domain in domains for r in bench_scaling(domain, args.steps, args.seed)]
        print(f"\n{'domain':<16}{'size':>9}{'agents':>8}{'GS steps/s':>12}"
              f"{'GS µs/step':>12}{'IALS single µs':>16}{'IALS batched µs/agent':>23}")
        for r in rows:
            print(f"{r['domain']:<16}{'x'.join(map(str, r['size'])):>9}{r['agents']:>8}"
                  f"{r['gs_steps_per_s']:>12,.0f}{r['gs_us_per_step']:>12,.0f}"
                  f"{r['ials_single_us_per_step']:>16,.1f}{r['ials_us_per_agent_step']:>23,.1f}")
        plot_scaling(rows, args.plot)
        print(f"plot: {args.plot}")
    else:
        rows = []
        for domain in domains:
            rows.append(bench_domain(domain, args.steps, args.batch, args.predictor, args.seed, args.repeats))
            print_domain(rows[-1])
        if len(rows) > 1:
            for line in verdict(rows):
                print(line)
    if args.out:
        atomic_write_text(args.out, json.dumps({"machine": machine, "rows": rows}, indent=2) + "\n")
        print(f"figures written to {args.out}")
    return 0
