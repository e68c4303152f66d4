"""Calibration of the traffic demand under all-actuated control (SPEC §2).

Runs ``episodes`` episodes of the grid in which every intersection, the observed ones
included, runs SUMO's actuated program (``scripted_learners=True``), and reports over time:
the vehicles in the network, the insertion backlog (vehicles due to depart but not yet
inserted, ``simulation.getPendingVehicles``), the teleports so far (summed
``simulation.getStartingTeleportNumber``), and the actuated controller's mean episodic
reward (sum over the first ``max_cycles`` steps) at the observed intersections.

Usage::

    ials-zoo calibrate [--episodes 5] [--steps 600] [--grid 5 5]
"""

from __future__ import annotations

import time

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.traffic.env import TrafficGridEnv


def calibrate(
    episodes: int = 5,
    steps: int = 600,
    agents=("tls_12", "tls_18"),
    grid=(5, 5),
    max_cycles: int = 300,
    seed: int = 0,
    report_every: int = 50,
    verbose: bool = True,
) -> dict:
    """Run the calibration and return its figures.

    Returns:
        ``{"times": [...], "vehicles": [...], "pending": [...], "teleports": [...],
        "reward": {agent: (mean, std)}, "steps_per_s": float, ...}`` where the time series
        are means over episodes at ``times`` (every ``report_every`` steps up to ``steps``);
        the rewards are episodic sums over the first ``max_cycles`` steps.
    """
    if steps < max_cycles:
        raise BadInput(f"steps ({steps}) must be >= max_cycles ({max_cycles})")
    env = TrafficGridEnv(
        learners=list(agents), grid=grid, max_cycles=steps, scripted_learners=True
    )
    times = list(range(report_every, steps + 1, report_every))
    veh = np.zeros((episodes, len(times)))
    pend = np.zeros((episodes, len(times)))
    tele = np.zeros((episodes, len(times)))
    rewards = {a: [] for a in env.possible_agents}
    t0 = time.perf_counter()
    try:
        for ep in range(episodes):
            env.reset(seed=seed + ep)
            ret = dict.fromkeys(env.possible_agents, 0.0)
            teleports = 0
            j = 0
            for t in range(1, steps + 1):
                _, r, _, _, _ = env.step(dict.fromkeys(env.agents, 0))
                if t <= max_cycles:
                    for a, v in r.items():
                        ret[a] += v
                s = env.simulation_stats()
                teleports += s["teleports"]
                if j < len(times) and t == times[j]:
                    veh[ep, j], pend[ep, j], tele[ep, j] = s["vehicles"], s["pending"], teleports
                    j += 1
            for a in ret:
                rewards[a].append(ret[a])
    finally:
        env.close()
    elapsed = time.perf_counter() - t0
    out = {
        "grid": list(grid),
        "episodes": episodes,
        "times": times,
        "vehicles": veh.mean(0).tolist(),
        "pending": pend.mean(0).tolist(),
        "pending_max": pend.max(0).tolist(),
        "teleports": tele.mean(0).tolist(),
        "reward": {a: (float(np.mean(v)), float(np.std(v))) for a, v in rewards.items()},
        "reward_episodes": {a: [float(x) for x in v] for a, v in rewards.items()},
        "max_cycles": max_cycles,
        "steps_per_s": episodes * steps / elapsed,
    }
    if verbose:
        print(format_report(out))
    return out


def format_report(out: dict) -> str:
    lines = [
        f"traffic_grid_v0 calibration: {out['grid'][0]}x{out['grid'][1]} grid, all actuated, "
        f"{out['episodes']} episodes from an empty network",
        f"{'time (s)':>9} {'vehicles':>9} {'backlog':>8} {'backlog max':>12} {'teleports':>10}",
    ]
    for t, v, p, pm, tp in zip(
        out["times"], out["vehicles"], out["pending"], out["pending_max"], out["teleports"]
    ):
        lines.append(f"{t:>9d} {v:>9.1f} {p:>8.1f} {pm:>12.0f} {tp:>10.1f}")
    lines.append(f"actuated mean episodic reward over {out['max_cycles']} steps:")
    for a, (m, s) in out["reward"].items():
        lines.append(f"  {a}: {m:.1f} +- {s:.1f}")
    lines.append(f"({out['steps_per_s']:.0f} GS steps/s including the stats queries)")
    return "\n".join(lines)


def configure(parser) -> None:
    """``ials-zoo calibrate``'s options."""
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--steps", type=int, default=600, help="steps per episode (>= 300)")
    parser.add_argument("--grid", type=int, nargs=2, default=(5, 5), metavar=("ROWS", "COLS"))
    parser.add_argument("--agents", nargs="+", default=["tls_12", "tls_18"])
    parser.add_argument("--seed", type=int, default=0)


def run(args) -> int:
    if args.episodes < 1:
        raise BadInput(f"--episodes must be >= 1, got {args.episodes}")
    calibrate(args.episodes, args.steps, args.agents, tuple(args.grid), seed=args.seed)
    return 0
