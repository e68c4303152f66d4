"""The speed of ``sumo_net_v0``'s GS against raw SUMO on the same traffic, per map.

Every light learns and acts at random (as at the start of training). Raw SUMO's cost is
measured inside the same episode: the wall-clock of SUMO's own start (loading the network),
``simulationStep`` calls and end (``close``: the last tripinfo written), the simulation the GS
asked for and nothing else. The GS's share of
raw speed is that time over the GS's whole wall-clock from ``reset`` to the last step
(observing, rewards, the Python env, and in the default mode a fresh
worker process per episode, forked from a zygote, and one pipe round trip per decision). One ratio per episode, taken
in one run, so machine load largely cancels out; median [min, max] over ``repeats`` episodes
(seeds 0, 1, ...), for two modes: the env's default (``fresh_process=True``: every episode in
a new worker, which makes episodes reproducible) and in this process (``fresh_process=False``).
Reading the episode's tripinfo for its metrics (RESCO's delay) is timed apart: only an
evaluation asks for it, a training loop never does.

Then the IALS against the GS: every light's at once, per agent-decision, both ParallelEnvs in a
worker (:func:`bench_local`), and each light's own, decisions per second (:func:`bench_single`);
and every light's IALS on SUMO regions against the same on arrays, 1 and 64 copies in a batch
(:func:`bench_arrays`).
"""

from __future__ import annotations

import time

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.learners.gs_vec import GSVecEnv
from ials_zoo.sumo.lease import SimulationError
from ials_zoo.sumo_net.arrays_vec import ArrayIALSCopies
from ials_zoo.sumo_net.env import SumoNetEnv
from ials_zoo.sumo_net.ials_env import IALSNetEnv
from ials_zoo.sumo_net.island import gs_marginal_predictors
from ials_zoo.sumo_net.names import DEFAULT_NET, ENV_ID, SCENARIO_OPTIONS
from ials_zoo.sumo_net.network import read_network
from ials_zoo.sumo_net.scenario import RESCO_MAPS, scenario_of

DEFAULT_MAPS = ("cologne8", "grid4x4", "ingolstadt21")

# wall-clock per simulated second of the GS in its default mode: cologne8 116.2 and grid4x4 76.0
# decisions/s with every light at random (this benchmark, 5 episodes, quiet 2-core machine, at the GS
# of commit 352322a); ingolstadt21 10.4 decisions/s (the GS with one learner among lights on their own
# programs, docs/sumo_net.md "One junction's IALS": SUMO's steps dominate there, whoever acts). Another
# network is charged per lane (internal lanes included) at ingolstadt21's rate, the costliest measured.
SIM_SECOND_SECONDS = {"cologne8": 1 / 116.2 / 10, "grid4x4": 1 / 76.0 / 10, "ingolstadt21": 1 / 10.4 / 10}
LANE_SIM_SECOND_SECONDS = 1 / 10.4 / 10 / 3746


def gs_step_seconds(**options) -> float:
    """About how long one GS decision takes under ``options`` (every light acting, the default
    mode), for the estimates long commands print first: a measured map's figure, else
    :data:`LANE_SIM_SECOND_SECONDS` per lane of the network."""

    chosen = {k: v for k, v in options.items() if k in SCENARIO_OPTIONS and k != "max_cycles"}
    scenario = scenario_of(**chosen)
    named = set(chosen) - {"begin", "end"} <= {"net"}  # a measured map's hour or part of it
    per_second = SIM_SECOND_SECONDS.get(chosen.get("net", DEFAULT_NET)) if named else None
    if per_second is None:
        per_second = LANE_SIM_SECOND_SECONDS * len(read_network(scenario.net_file).lane_edges)
    return per_second * scenario.decision_seconds
MODES = {"default (fresh worker per episode)": {}, "in this process": {"backend": "inprocess", "fresh_process": False}}


def _stat(xs):
    return [float(np.median(xs)), float(np.min(xs)), float(np.max(xs))]


def bench_map(net: str, repeats: int = 3, max_cycles: int | None = None, mode: str = "in this process") -> dict:
    """One map's figures in one mode: decisions/s, µs per agent-decision, SUMO steps/s, share of raw."""
    env = SumoNetEnv(net=net, max_cycles=max_cycles, **MODES[mode])
    rng = np.random.default_rng(0)
    shares, decisions_per_s, raw_steps_per_s, metrics_s = [], [], [], []
    try:
        if env.fresh_process:  # the zygote that forks the workers starts once per process: not timed
            env.reset(seed=repeats)
        for seed in range(repeats):
            # a fresh worker's core starts its clock at zero; this process's keeps counting
            before = env._sim.call("timing") if not env.fresh_process and seed else 0.0
            # the random policy's draws are made before the clock starts: they are not the GS's cost
            draws = {a: rng.integers(env.action_space(a).n, size=env.scenario.decisions).tolist()
                     for a in env.possible_agents}
            t0, n = time.perf_counter(), 0
            env.reset(seed=seed)
            while env.agents:
                env.step({a: draws[a][n] for a in env.agents})
                n += 1
            wall = time.perf_counter() - t0
            sim = env._sim.call("timing") - before  # the episode's worker lives until the next reset
            t0 = time.perf_counter()
            env.episode_metrics()  # what an evaluation adds to the episode (training never reads them)
            metrics_s.append(time.perf_counter() - t0)
            shares.append(sim / wall)
            decisions_per_s.append(n / wall)
            raw_steps_per_s.append(n * env.scenario.decision_seconds / sim)
        agents = len(env.possible_agents)
    finally:
        env.close()
    return {"net": net, "mode": mode, "agents": agents, "repeats": repeats,
            "gs_share_of_raw": _stat(shares), "gs_decisions_per_s": _stat(decisions_per_s),
            "us_per_agent_decision": _stat([1e6 / (d * agents) for d in decisions_per_s]),
            "raw_sumo_steps_per_s": _stat(raw_steps_per_s), "metrics_read_s": _stat(metrics_s)}


def print_rows(rows) -> None:
    print(f"\n{'map':<14}{'mode':<36}{'lights':>7}{'GS decisions/s':>22}{'µs/agent-decision':>19}"
          f"{'raw SUMO steps/s':>18}{'GS / raw SUMO':>22}{'metrics read (ms)':>19}")
    for r in rows:
        def f(key, fmt):
            m, lo, hi = r[key]
            return f"{m:{fmt}} [{lo:{fmt}}, {hi:{fmt}}]"
        print(f"{r['net']:<14}{r['mode']:<36}{r['agents']:>7}{f('gs_decisions_per_s', '.1f'):>22}"
              f"{r['us_per_agent_decision'][0]:>19,.0f}{r['raw_sumo_steps_per_s'][0]:>18,.0f}"
              f"{f('gs_share_of_raw', '.2f'):>22}{r['metrics_read_s'][0] * 1e3:>19,.0f}")
    print("GS / raw SUMO: the share of the GS's wall-clock (reset to the last step) spent in SUMO's own start and "
          "steps of the same episode (1.0 = no overhead); median [min, max] over the repeats. All lights random. "
          "Metrics read: reading the episode's tripinfo (RESCO's delay), which only an evaluation asks for.")


def _random_episode(env, seed: int) -> float:
    """Seconds per decision of one episode with every light at random (drawn before the clock)."""
    rng = np.random.default_rng(seed)
    draws = {a: rng.integers(env.action_space(a).n, size=env.scenario.decisions).tolist() for a in env.possible_agents}
    start, n = time.perf_counter(), 0
    env.reset(seed=seed)
    while env.agents:
        env.step({a: draws[a][n] for a in env.agents})
        n += 1
    return (time.perf_counter() - start) / n


def _random_vector_episode(env, counts: list[int], decisions: int, seed: int) -> float:
    """Seconds per decision of one episode of an array env (every light at random)."""
    rng = np.random.default_rng(seed)
    draws = np.stack([rng.integers(n, size=(decisions, env.n_envs)) for n in counts], axis=1)  # [T, A, copies]
    start, n, done = time.perf_counter(), 0, False
    env.reset(seed=seed)
    while not done:
        _, _, done = env.step(draws[n])
        n += 1
    return (time.perf_counter() - start) / n


def bench_local(net: str, repeats: int = 3, max_cycles: int | None = None) -> dict:
    """The multi-agent IALS (:class:`ials_zoo.sumo_net.ials_env.IALSNetEnv`, every light's AIP
    the GS's recorded entry frequencies: :func:`~ials_zoo.sumo_net.island.gs_marginal_predictors`)
    against the GS, per agent-decision: both in a worker process (one pipe round trip per
    decision each), episodes of the same seed alternating, one ratio per pair; and the array API
    (:func:`ials_zoo.make_ials_vector_env`, one copy in this process's own worker) in the same turn."""

    options = {"net": net, "backend": "worker", "fresh_process": False, "max_cycles": max_cycles}
    start = time.perf_counter()
    gs = SumoNetEnv(**options)
    local = vector = None
    runs = []
    try:
        aips = gs_marginal_predictors(gs.possible_agents, net=net, max_cycles=max_cycles)
        local = IALSNetEnv(predictors=aips, **options)
        built = time.perf_counter() - start
        vector = GSVecEnv(ENV_ID, None, 1, 0, 0, simulator="ials", predictor=aips, **options)  # make_ials_vector_env's
        counts = [gs.action_space(a).n for a in gs.possible_agents]
        for seed in range(repeats):
            runs.append((_random_episode(gs, seed), _random_episode(local, seed),
                         _random_vector_episode(vector, counts, gs.scenario.decisions, seed)))
    finally:
        gs.close()
        for env in (local, vector):
            if env is not None:
                env.close()
    agents = len(gs.possible_agents)
    return {"net": net, "agents": agents, "repeats": repeats, "build_seconds": built,
            "gs_us_per_agent_decision": _stat([g / agents * 1e6 for g, _, _ in runs]),
            "local_us_per_agent_decision": _stat([x / agents * 1e6 for _, x, _ in runs]),
            "local_over_gs": _stat([x / g for g, x, _ in runs]),
            "array_over_gs": _stat([v / g for g, _, v in runs])}


def bench_single(net: str, repeats: int = 3, max_cycles: int | None = None) -> dict:
    """Every light's own IALS (``make_ials``, the recorded-frequency AIP) against the GS with one
    learner, decisions per second, both in this process; the GS's median over ``repeats`` episodes
    of its first light learning, each IALS one episode."""
    from ials_zoo.influence.ials import make_ials

    gs = SumoNetEnv(net=net, max_cycles=max_cycles, backend="inprocess", fresh_process=False)
    lights = list(gs.possible_agents)
    gs.close()
    gs = SumoNetEnv(net=net, max_cycles=max_cycles, backend="inprocess", fresh_process=False, learners=lights[:1])
    try:
        gs_rate = float(np.median([1.0 / _random_episode(gs, seed) for seed in range(repeats)]))
    finally:
        gs.close()
    aips, rates = gs_marginal_predictors(lights, net=net, max_cycles=max_cycles), []
    for k, light in enumerate(lights):
        env = make_ials(ENV_ID, light, predictor=aips[light], seed=k, net=net, max_cycles=max_cycles)
        try:
            rng = np.random.default_rng(k)
            env.reset(seed=k)
            start, n, done = time.perf_counter(), 0, False
            while not done:
                *_, term, trunc, _ = env.step(int(rng.integers(env.action_space.n)))
                n, done = n + 1, term or trunc
            rates.append(n / (time.perf_counter() - start))
        finally:
            env.close()
    return {"net": net, "agents": len(lights), "gs_decisions_per_s": gs_rate,
            "ials_decisions_per_s": _stat(rates), "speedup": _stat([r / gs_rate for r in rates])}


ARRAY_COPIES = (1, 64)


def _ials_episode(env, decisions: int, seed: int) -> float:
    """Seconds per decision of every light's IALS (``ArrayIALSCopies`` or a ``GSVecEnv``-like
    batch) over ``decisions`` decisions, every light at random (drawn before the clock)."""
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, 2**31, size=(decisions, len(env.agents), env.copies))
    counts = np.array([[n] for n in env.action_counts])
    start = time.perf_counter()
    env.reset([seed + j for j in range(env.copies)])
    for n in range(decisions):
        env.step(draws[n] % counts)
    return (time.perf_counter() - start) / decisions


def _regions_episode(env, seed: int):
    """:func:`_random_episode` of the SUMO regions' IALS, or the SUMO error that stopped it
    (its cut renames some networks' roads: a generated grid's)."""
    try:
        return _random_episode(env, seed)
    except SimulationError as exc:
        return f"the SUMO regions failed: {str(exc).splitlines()[0][:200]}"


def bench_arrays(net: str, repeats: int = 3, decisions: int = 60, copies=ARRAY_COPIES) -> dict:
    """µs per agent-decision of the GS, every light's IALS on SUMO regions, and on arrays
    (:mod:`ials_zoo.sumo_net.arrays`) with each of ``copies`` copies in one batch; every light at
    random, AIPs of the GS's recorded entry frequencies, the first ``decisions`` decisions of the
    map's hour, interleaved ``repeats`` times: one ratio to the GS per turn. The GS and the
    arrays run in this process, the SUMO regions in a worker (one SUMO simulation per process:
    a pipe round trip per decision). Also the arrays' memory per copy (the vehicle pool's bytes)."""
    options = {"net": net, "fresh_process": False, "max_cycles": decisions}
    lights = read_network(scenario_of(net=net).net_file).ids
    # the entries of the measured decisions, recorded before the GS holds this process's SUMO
    aips = gs_marginal_predictors(lights, net=net, max_cycles=decisions)
    gs = SumoNetEnv(backend="inprocess", **options)
    local = IALSNetEnv(predictors=aips, backend="worker", **options)  # SUMO's one simulation per process
    arrays = {c: ArrayIALSCopies(None, aips, list(range(c)), net=net, max_cycles=decisions) for c in copies}
    turns, regions_failed = [], None
    try:
        for seed in range(repeats):
            turns.append((_random_episode(gs, seed), _regions_episode(local, seed),
                          {c: _ials_episode(env, decisions, seed) / c for c, env in arrays.items()}))
    finally:
        memory = {c: sum(getattr(env.core.sim.v, f).nbytes for f in vars(env.core.sim.v)) / c
                  for c, env in arrays.items()}
        for env in (gs, local, *arrays.values()):
            env.close()
    n = len(lights)
    regions = [(g, x) for g, x, _ in turns if not isinstance(x, str)]
    if len(regions) < len(turns):
        regions_failed = next(x for _, x, _ in turns if isinstance(x, str))
    out = {"net": net, "agents": n, "repeats": repeats, "decisions": decisions,
           "gs_us": _stat([g / n * 1e6 for g, _, _ in turns]), "bytes_per_copy": memory,
           "sumo_regions_us": _stat([x / n * 1e6 for _, x in regions]) if regions else None,
           "sumo_regions_over_gs": _stat([x / g for g, x in regions]) if regions else None,
           "sumo_regions_failed": regions_failed}
    for c in copies:
        out[f"arrays_{c}_us"] = _stat([a[c] / n * 1e6 for _, _, a in turns])
        out[f"arrays_{c}_over_gs"] = _stat([a[c] / g for g, _, a in turns])
    return out


def print_array_rows(rows) -> None:
    rows = [r for r in rows if "sumo_regions_over_gs" in r]
    if not rows:
        return
    copies = sorted(int(k.split("_")[1]) for k in rows[0] if k.startswith("arrays_") and k.endswith("_us"))
    print(f"\n{'map':<14}{'lights':>7}{'GS µs':>9}{'SUMO regions / GS':>22}"
          + "".join(f"{f'arrays x{c} / GS':>22}" for c in copies) + f"{'KiB per copy':>14}")
    for r in rows:
        def f(key):
            m, lo, hi = r[key]
            return f"{m:.3f} [{lo:.3f}, {hi:.3f}]"
        regions = f("sumo_regions_over_gs") if r["sumo_regions_over_gs"] else "failed"
        print(f"{r['net']:<14}{r['agents']:>7}{r['gs_us'][0]:>9,.0f}{regions:>22}"
              + "".join(f"{f(f'arrays_{c}_over_gs'):>22}" for c in copies)
              + f"{r['bytes_per_copy'][copies[-1]] / 1024:>14,.0f}")
    print("µs per agent-decision over the GS's, every light's IALS at once (AIPs of the GS's entry frequencies, every "
          "light random), the first decisions of the map's hour; the GS and the arrays in this process, the SUMO "
          "regions in a worker; median [min, max] over interleaved turns. Arrays xN: N copies in one batch, per copy.")


def print_local_rows(rows) -> None:
    multi = [r for r in rows if "local_over_gs" in r]
    print(f"\n{'map':<14}{'lights':>7}{'GS µs/agent-decision':>22}{'IALS µs/agent-decision':>24}"
          f"{'IALS / GS':>22}{'arrays / GS':>22}{'built in':>10}")
    for r in multi:
        m, lo, hi = r["local_over_gs"]
        am, alo, ahi = r["array_over_gs"]
        print(f"{r['net']:<14}{r['agents']:>7}{r['gs_us_per_agent_decision'][0]:>22,.0f}"
              f"{r['local_us_per_agent_decision'][0]:>24,.0f}{f'{m:.2f} [{lo:.2f}, {hi:.2f}]':>22}"
              f"{f'{am:.2f} [{alo:.2f}, {ahi:.2f}]':>22}{r['build_seconds']:>9.0f}s")
    print("The multi-agent IALS: every light's region side by side in one SUMO simulation, each fed by an AIP of the "
          "GS's recorded entry frequencies (a trained MLP costs one call more per light and decision); IALS: the "
          "ParallelEnv, arrays: the same as make_ials_vector_env gives it (what DIALS steps); built in: cutting, "
          "merging, recording. Median [min, max] over episode triples.")
    header = "one light's IALS decisions/s"
    print(f"\n{'map':<14}{'lights':>7}{'GS decisions/s':>16}{header:>32}{'speed-up':>24}")
    for r in (r for r in rows if "speedup" in r):
        m, lo, hi = r["speedup"]
        print(f"{r['net']:<14}{r['agents']:>7}{r['gs_decisions_per_s']:>16,.1f}"
              f"{r['ials_decisions_per_s'][0]:>32,.0f}{f'{m:.1f}x [{lo:.1f}x, {hi:.1f}x]':>24}")
    print("One light's IALS (make_ials) against the GS with that one learner, both in this process; median [min, "
          "max] over the lights.")


def run_bench(nets=DEFAULT_MAPS, repeats: int = 3, max_cycles: int | None = None, local: bool = True) -> list[dict]:
    """Measure and print every map of ``nets`` in both modes, and (``local``) its local simulators."""
    unknown = [n for n in nets if n not in RESCO_MAPS]
    if unknown:
        raise BadInput(f"--net: unknown map(s) {unknown}; expected some of {', '.join(RESCO_MAPS)}")
    rows, local_rows = [], []
    for net in nets:
        for mode in MODES:
            rows.append(bench_map(net, repeats, max_cycles, mode))
            print(f"{net}, {mode}: GS at {rows[-1]['gs_share_of_raw'][0]:.2f} of raw SUMO", flush=True)
        if local:
            local_rows.append(bench_local(net, repeats, max_cycles))
            print(f"{net}, the multi-agent IALS: {local_rows[-1]['local_over_gs'][0]:.2f} of the GS per agent-decision",
                  flush=True)
            local_rows.append(bench_single(net, repeats, max_cycles))
            print(f"{net}, one light's IALS: {local_rows[-1]['speedup'][0]:.1f}x the GS's decisions/s", flush=True)
            local_rows.append(bench_arrays(net, repeats))
            print(f"{net}, every light's IALS on arrays x{ARRAY_COPIES[-1]}: "
                  f"{local_rows[-1][f'arrays_{ARRAY_COPIES[-1]}_over_gs'][0]:.3f} of the GS per agent-decision", flush=True)
    print_rows(rows)
    if local_rows:
        print_local_rows(local_rows)
        print_array_rows(local_rows)
    return rows + local_rows


__all__ = ["ARRAY_COPIES", "DEFAULT_MAPS", "MODES", "bench_arrays", "bench_local", "bench_map", "bench_single", "print_local_rows", "print_rows",
           "run_bench"]
