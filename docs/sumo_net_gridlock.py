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

Usage: python docs/sumo_net_gridlock.py POLICY --lights A,B [--net ingolstadt21] [--episodes 2]
       python docs/sumo_net_gridlock.py --results RESULT [RESULT ...] [--jam -200]
"""

from __future__ import annotations

import argparse

import numpy as np

from ials_zoo.core.domains import get_domain
from ials_zoo.evaluation import load_model
from ials_zoo.influence.fidelity import joint_sizes, on_policy_aips, run
from ials_zoo.influence.multi import make_ials_parallel_env
from ials_zoo.leaderboard.validate import load_result
from ials_zoo.sumo_net.influence import region_spec

ENV_ID = "sumo_net_v0"


def trajectories(policy_file: str, lights: list[str], episodes: int, options: dict) -> dict:
    """``{"GS": Trajectories, "IALS": Trajectories}`` of ``lights`` under the joint policy."""
    domain = get_domain(ENV_ID)
    agents = domain.agents(**options)
    sizes = joint_sizes(domain, agents, options)
    policy = load_model(policy_file)
    gs_env = domain.parallel_env(learners=agents, **{**domain.collect_options, **options})
    try:
        gs = run(gs_env, agents, lights, policy, episodes, 0, sizes)
    finally:
        gs_env.close()
    aips = on_policy_aips(ENV_ID, agents, policy, 720, 100_000, False, options, width=sizes.obs_size)
    ials_env = make_ials_parallel_env(ENV_ID, agents, predictor=aips, seed=0, **options)
    try:
        ials = run(ials_env, agents, lights, policy, episodes, 0, sizes)
    finally:
        ials_env.close()
    return {"GS": gs, "IALS": ials}


def exit_lines(light: str, runs: dict, options: dict) -> list[str]:
    """Per simulator: the light's returns, and per exit its blocked share and stay chance."""
    names = region_spec(light, **options).influence_names
    exits = [k for k, n in enumerate(names) if n.startswith("exit:")]
    lines = [f"{light}: " + ", ".join(f"{label} returns {np.round(t.returns[light], 1).tolist()}"
                                      for label, t in runs.items())]
    for label, t in runs.items():
        cells = []
        for k in exits:
            per_episode = [u[:, k] for u in t.influence[light]]
            blocked = np.concatenate(per_episode)
            before = np.concatenate([x[:-1] for x in per_episode])
            after = np.concatenate([x[1:] for x in per_episode])
            stay = f"{(after[before == 1] == 1).mean():.2f}" if (before == 1).any() else "-"
            cells.append(f"{names[k][5:]} {blocked.mean():.2f} (stay {stay})")
        lines.append(f"  {label}: exits blocked " + ", ".join(cells))
    return lines


def result_lines(files: list[str], jam: float) -> list[str]:
    """Per result file: its evaluation's returns per episode, summarised."""
    lines = []
    for f in files:
        returns = np.asarray(load_result(f)["scores"][0]["returns"], float)
        lines.append(f"{f}: median {np.median(returns):.1f}, mean {returns.mean():.1f}, "
                     f"{int((returns < jam).sum())} of {returns.size} episodes below {jam:g}")
    return lines


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy", nargs="?", help="a joint policy file")
    parser.add_argument("--lights", default="", help="watched lights, comma-separated")
    parser.add_argument("--net", default="ingolstadt21")
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--results", nargs="+", help="result files: list their returns per episode instead")
    parser.add_argument("--jam", type=float, default=-200.0, help="an episode return below this is a jam")
    args = parser.parse_args(argv)
    if args.results:
        print("\n".join(result_lines(args.results, args.jam)))
        return
    lights = [x for x in args.lights.split(",") if x]
    if not args.policy or not lights:
        parser.error("give a policy file and --lights (or --results)")
    if args.episodes < 1:
        parser.error(f"--episodes must be >= 1, got {args.episodes}")
    options = {"net": args.net}
    runs = trajectories(args.policy, lights, args.episodes, options)
    for light in lights:
        print("\n".join(exit_lines(light, runs, options)))


if __name__ == "__main__":
    main()
