"""The speed of ``sumo_net_v0``'s GS against raw SUMO on the same traffic, per map.

Every light learns and acts at random (as at the start of training), in this process. Raw
SUMO's cost is measured inside the same episode: the wall-clock of SUMO's own
``simulationStep`` calls, the simulation the GS asked for and nothing else; the GS's share of
raw speed is that time over the GS's whole wall-clock (observing, rewards, the Python env,
SUMO's tripinfo output). One ratio per episode, taken in one run, so machine load cancels
out; median [min, max] over ``repeats`` episodes (seeds 0, 1, ...).
"""

from __future__ import annotations

import time

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.sumo_net.env import SumoNetEnv
from ials_zoo.sumo_net.scenario import RESCO_MAPS

DEFAULT_MAPS = ("cologne8", "grid4x4", "ingolstadt21")


def bench_map(net: str, repeats: int = 3, max_cycles: int | None = None) -> dict:
    """One map's figures: GS decisions/s, µs per agent-decision, SUMO steps/s, share of raw."""
    env = SumoNetEnv(net=net, max_cycles=max_cycles, backend="inprocess", fresh_process=False)
    rng = np.random.default_rng(0)
    shares, decisions_per_s, raw_steps_per_s = [], [], []
    try:
        for seed in range(repeats):
            env.reset(seed=seed)
            sim0, t0, n = env._sim.call("timing"), time.perf_counter(), 0
            while env.agents:
                env.step({a: int(rng.integers(env.action_space(a).n)) for a in env.agents})
                n += 1
            wall, sim = time.perf_counter() - t0, env._sim.call("timing") - sim0
            shares.append(sim / wall)
            decisions_per_s.append(n / wall)
            raw_steps_per_s.append(n * env.scenario.decision_seconds / sim)
        agents = len(env.possible_agents)
        lanes = sum(len(x.lanes) for x in env.network.lights)
    finally:
        env.close()

    def stat(xs):
        return [float(np.median(xs)), float(np.min(xs)), float(np.max(xs))]

    return {"net": net, "agents": agents, "lanes": lanes, "repeats": repeats,
            "gs_share_of_raw": stat(shares), "gs_decisions_per_s": stat(decisions_per_s),
            "us_per_agent_decision": stat([1e6 / (d * agents) for d in decisions_per_s]),
            "raw_sumo_steps_per_s": stat(raw_steps_per_s)}


def print_rows(rows) -> None:
    print(f"\n{'map':<14}{'lights':>7}{'GS decisions/s':>24}{'µs/agent-decision':>20}{'raw SUMO steps/s':>19}"
          f"{'GS / raw SUMO':>22}")
    for r in rows:
        def f(key, fmt):
            m, lo, hi = r[key]
            return f"{m:{fmt}} [{lo:{fmt}}, {hi:{fmt}}]"
        print(f"{r['net']:<14}{r['agents']:>7}{f('gs_decisions_per_s', '.1f'):>24}{r['us_per_agent_decision'][0]:>20,.0f}"
              f"{r['raw_sumo_steps_per_s'][0]:>19,.0f}{f('gs_share_of_raw', '.2f'):>22}")
    print("GS / raw SUMO: the share of the GS's wall-clock spent in SUMO's own steps of the same episode "
          "(1.0 = no overhead); median [min, max] over the repeats. All lights random, in-process.")


def run_bench(nets=DEFAULT_MAPS, repeats: int = 3, max_cycles: int | None = None) -> list[dict]:
    """Measure and print every map of ``nets``."""
    rows = []
    unknown = [n for n in nets if n not in RESCO_MAPS]
    if unknown:
        raise BadInput(f"--net: unknown map(s) {unknown}; expected some of {', '.join(RESCO_MAPS)}")
    for net in nets:
        rows.append(bench_map(net, repeats, max_cycles))
        print(f"{net}: GS at {rows[-1]['gs_share_of_raw'][0]:.2f} of raw SUMO", flush=True)
    print_rows(rows)
    return rows


__all__ = ["DEFAULT_MAPS", "bench_map", "print_rows", "run_bench"]
