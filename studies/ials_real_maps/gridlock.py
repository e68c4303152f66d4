"""Jams the IALS cannot start: under one joint policy, how often each watched light's exits are
blocked, and how long a block lasts, in the GS and in the multi-agent IALS.

For every watched light: its return per episode in each simulator, and per exit of its region
(:mod:`ials_zoo.sumo_net.influence`: an exit is blocked for a decision when a vehicle halts in
its first metres for half the decision or more) the share of decisions blocked and the chance
that a blocked exit is blocked again at the next decision ("stay"). The IALS's AIPs are trained
on 720 GS decisions of the same policy (``ials-zoo fidelity --predictor on-policy``'s). The GS
episodes are the fidelity study's (seeds 0, 1, ...).

``--results`` instead lists result files' evaluation returns per episode: median, mean and how
many episodes fell below ``--jam`` (a jammed episode).

``--release`` runs the GS alone, three episodes of each joint policy (a policy file, or
``random``), and counts over every light's exits how often a block that has lasted at least N
decisions ends at the next one (what ``GRIDLOCK_DECISIONS`` of :mod:`ials_zoo.sumo_net.island`
rests on).

Usage: python studies/ials_real_maps/gridlock.py POLICY --lights A,B [--net ingolstadt21] [--episodes 2] [--autoregressive]
                                         [--clock H]
       python studies/ials_real_maps/gridlock.py --results RESULT [RESULT ...] [--jam -200]
       python studies/ials_real_maps/gridlock.py --release POLICY|random [...] [--net ingolstadt21]
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from ials_zoo.core.domains import get_domain
from ials_zoo.evaluation import load_model
from ials_zoo.influence.fidelity import joint_sizes, on_policy_aips, run
from ials_zoo.influence.multi import make_ials_parallel_env
from ials_zoo.leaderboard.validate import load_result
from ials_zoo.sumo_net.influence import region_spec

ENV_ID = "sumo_net_v0"
MAX_PROGRESS_BYTES = 16 << 20  # a run's progress.csv is read whole


def trajectories(policy_file: str, lights: list[str], episodes: int, options: dict,
                 autoregressive: bool = False, clock: int = 0) -> dict:
    """``{"GS": Trajectories, "IALS": Trajectories}`` of ``lights`` under the joint policy (the
    IALS's AIPs autoregressive if asked, as ``--predictor on-policy-autoregressive``'s, and reading
    the time since the episode's start if ``clock`` > 0, as ``--aip-clock-horizon``)."""
    domain = get_domain(ENV_ID)
    agents = domain.agents(**options)
    sizes = joint_sizes(domain, agents, options)
    policy = load_model(policy_file)
    gs_env = domain.parallel_env(learners=agents, **{**domain.collect_options, **options})
    try:
        gs = run(gs_env, agents, lights, policy, episodes, 0, sizes)
    finally:
        gs_env.close()
    aips = on_policy_aips(ENV_ID, agents, policy, 720, 100_000, autoregressive, options, clock_horizon=clock,
                          width=sizes.obs_size)
    ials_env = make_ials_parallel_env(ENV_ID, agents, predictor=aips, seed=0, **options)
    try:
        ials = run(ials_env, agents, lights, policy, episodes, 0, sizes)
    finally:
        ials_env.close()
    return {"GS": gs, "IALS": ials}


def exit_lines(light: str, runs: dict, options: dict) -> list[str]:
    """Per simulator: the light's returns, per exit its blocked share and stay chance, and the
    decision its busiest exit is first blocked in each episode (the onset of a jam)."""
    names = region_spec(light, **options).influence_names
    exits = [k for k, n in enumerate(names) if n.startswith("exit:")]
    lines = [f"{light}: " + ", ".join(f"{label} returns {np.round(t.returns[light], 1).tolist()}"
                                      for label, t in runs.items())]
    for label, t in runs.items():
        cells, busiest = [], max(exits, key=lambda k: sum(u[:, k].sum() for u in t.influence[light]))
        for k in exits:
            per_episode = [u[:, k] for u in t.influence[light]]
            blocked = np.concatenate(per_episode)
            before = np.concatenate([x[:-1] for x in per_episode])
            after = np.concatenate([x[1:] for x in per_episode])
            stay = f"{(after[before == 1] == 1).mean():.2f}" if (before == 1).any() else "-"
            cells.append(f"{names[k][5:]} {blocked.mean():.2f} (stay {stay})")
        lines.append(f"  {label}: exits blocked " + ", ".join(cells))
        onsets = [_onsets(u[:, busiest]) for u in t.influence[light]]
        lines.append(f"  {label}: {names[busiest][5:]} per episode (first blocked, blocked to the end from): {onsets}")
    return lines


def _onsets(blocked: np.ndarray) -> tuple:
    """The first blocked decision, and where the block that lasts to the episode's end began."""
    if not blocked.any():
        return (None, None)
    free = np.nonzero(blocked == 0)[0]
    last_free = int(free[-1]) if free.size else -1
    return (int(np.argmax(blocked)), last_free + 1 if last_free + 1 < blocked.size else None)


RUNS = (1, 3, 10, 30)  # decisions a block has lasted


def release_line(policy: str, options: dict) -> str:
    """Over every light's exits in three GS episodes of ``policy``: per N of :data:`RUNS`, the
    decisions after a block had lasted N or more, and how many of them it ended."""
    from ials_zoo.influence.dataset import collect_all
    from ials_zoo.influence.fidelity import _PolicyActor

    domain = get_domain(ENV_ID)
    agents = domain.agents(**options)
    actor = None if policy == "random" else _PolicyActor(load_model(policy), agents, 7,
                                                          joint_sizes(domain, agents, options).obs_size)
    data = collect_all(ENV_ID, agents, steps=3 * 360, policy=actor, seed=7, gs_options=options, progress=False)
    after, ended = dict.fromkeys(RUNS, 0), dict.fromkeys(RUNS, 0)
    for light, ds in data.items():
        names = region_spec(light, **options).influence_names
        for k in (k for k, n in enumerate(names) if n.startswith("exit:")):
            for u in ds.influences[:, :, k]:
                lasted = _lasted(u)
                for n in RUNS:
                    after[n] += int((lasted >= n).sum())
                    ended[n] += int(((lasted >= n) & (u == 0)).sum())
    return f"{policy}: " + ", ".join(f"lasted {n}+: {ended[n]} of {after[n]} ended" for n in RUNS)


def _lasted(blocked: np.ndarray) -> np.ndarray:
    """Per decision, how many decisions in a row the exit had been blocked just before it."""
    lasted, run = np.zeros(blocked.size, np.int64), 0
    for t, b in enumerate(blocked):
        lasted[t], run = run, (run + 1 if b else 0)
    return lasted


def result_lines(files: list[str], jam: float) -> list[str]:
    """Per result file: its evaluation's returns per episode, summarised, its training's
    wall-clock (AIP rounds included) and, from the run's ``progress.csv`` beside it, the median
    speed of the learning between AIP rounds (steps per light and second)."""
    lines = []
    for f in files:
        result = load_result(f)
        returns = np.asarray(result["scores"][0]["returns"], float)
        training = result.get("training", {})
        seconds = float(training.get("wall_clock_seconds") or 0) + float(training.get("aip_seconds") or 0)
        lines.append(f"{f}: median {np.median(returns):.1f}, mean {returns.mean():.1f}, "
                     f"{int((returns < jam).sum())} of {returns.size} episodes below {jam:g}; "
                     f"wall-clock {seconds:.0f} s ({float(training.get('aip_seconds') or 0):.0f} s AIP rounds)"
                     + _speed(Path(f).parent / "progress.csv"))
    return lines


def _speed(progress: Path) -> str:
    """The median steps per light and second between consecutive rows of one AIP round."""
    if not progress.is_file() or progress.stat().st_size > MAX_PROGRESS_BYTES:
        return ""
    with open(progress, newline="") as f:
        rows = list(csv.DictReader(f))
    rates = [(int(b["steps_per_agent"]) - int(a["steps_per_agent"]))
             / (float(b["wall_clock_seconds"]) - float(a["wall_clock_seconds"]))
             for a, b in zip(rows, rows[1:]) if a.get("aip_refreshes") == b.get("aip_refreshes")
             and float(b["wall_clock_seconds"]) > float(a["wall_clock_seconds"])]
    return f", learning at {np.median(rates):.0f} steps per light/s between AIP rounds" if rates else ""


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy", nargs="?", help="a joint policy file")
    parser.add_argument("--lights", default="", help="watched lights, comma-separated")
    parser.add_argument("--net", default="ingolstadt21")
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--autoregressive", action="store_true", help="AIPs that read their own last draws")
    parser.add_argument("--clock", type=int, default=0, help="AIPs that read the time, min(t, H) / H (0: no clock)")
    parser.add_argument("--results", nargs="+", help="result files: list their returns per episode instead")
    parser.add_argument("--jam", type=float, default=-200.0, help="an episode return below this is a jam")
    parser.add_argument("--release", nargs="+", help="joint policies (files or 'random'): how often long blocks end")
    args = parser.parse_args(argv)
    if args.release:
        for policy in args.release:
            print(release_line(policy, {"net": args.net}), flush=True)
        return
    if args.results:
        print("\n".join(result_lines(args.results, args.jam)))
        return
    lights = [x for x in args.lights.split(",") if x]
    if not args.policy or not lights:
        parser.error("give a policy file and --lights (or --results)")
    if args.clock < 0:
        parser.error(f"--clock must be >= 0, got {args.clock}")
    if args.episodes < 1:
        parser.error(f"--episodes must be >= 1, got {args.episodes}")
    options = {"net": args.net}
    runs = trajectories(args.policy, lights, args.episodes, options, args.autoregressive, args.clock)
    for light in lights:
        print("\n".join(exit_lines(light, runs, options)))


if __name__ == "__main__":
    main()
