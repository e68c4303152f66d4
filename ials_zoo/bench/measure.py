"""The bench's measurements: every timing of a domain, repeated and interleaved so a noisy
neighbour hits each alike, summed up as median [min, max]; and the other measurements the
command offers (growing systems, PPO's throughput, two AIP sets, AIP architectures)."""

from __future__ import annotations

import time
from importlib.metadata import version

import numpy as np
import torch
from tqdm.auto import tqdm

import ials_zoo
from ials_zoo.baselines.multiagent import PREVIOUS_PPO_SETTINGS
from ials_zoo.baselines.throughput import NO_SIMULATOR, ppo_bound, ppo_throughput
from ials_zoo.bench.report import fmt
from ials_zoo.bench.timings import (
    gs_seconds,
    ials_batched_seconds,
    ials_seconds,
    learner_seconds,
    multi_agent_seconds,
    parallel_env_seconds,
)
from ials_zoo.core.domains import Domain
from ials_zoo.core.extras import bench_of, dials_of
from ials_zoo.influence.multi import resolve_predictor_set
from ials_zoo.influence.networks import untrained_predictor
from ials_zoo.leaderboard import hardware_info


def machine_info() -> dict:
    """What the numbers were measured on: the leaderboard's ``hardware`` record
    (:func:`ials_zoo.leaderboard.hardware_info`) plus SUMO, torch's threads and the date."""

    hardware = hardware_info()
    try:
        sumo = version("eclipse-sumo")
    except Exception:  # not installed
        sumo = None
    return {"cpu": hardware["processor"], "cores": hardware["cpu_count"], "python": hardware["python"],
            "numpy": np.__version__, "torch": torch.__version__, "torch_threads": torch.get_num_threads(),
            "sumo": sumo, "ials_zoo": ials_zoo.__version__, "platform": hardware["platform"],
            "date": time.strftime("%Y-%m-%d %H:%M:%S")}


def summary(values) -> dict:
    """Median, min and max of repeated measurements."""
    v = np.asarray(values, float)
    return {"median": float(np.median(v)), "min": float(v.min()), "max": float(v.max()), "runs": [float(x) for x in v]}



def bench_domain(domain: Domain, steps: int | None, batch: int, predictor, seed: int, repeats: int) -> dict:
    """Every measurement of one domain, ``repeats`` times (module docstring)."""

    env_id = domain.env_id
    agent = domain.default_agents[0]
    agents = domain.agents()
    # 10 episodes per measurement: shorter ones swung several-fold on a shared machine
    steps = steps or 10 * domain.episode_length
    copies = dials_of(domain).copies
    print(f"[{env_id}] preparing the AIPs of {len(agents)} agents ({predictor}) ...", flush=True)
    aips = dict(zip(agents, resolve_predictor_set(predictor, env_id, agents, seed=seed)))
    runs: dict[str, list] = {k: [] for k in ("gs_one", "ials_one", "ials_batched", "gs_all", "ials_parallel",
                                             "ials_dials", "act", "update", "act_previous", "update_previous")}

    with tqdm(total=repeats * 8, desc=f"bench {env_id}", unit="measurement") as bar:
        for r in range(repeats):
            s = seed + r
            for key, fn in (
                ("gs_one", lambda: gs_seconds(domain, [agent], steps, s)),
                ("ials_one", lambda: ials_seconds(domain, agent, 3 * steps, s, predictor)),
                ("ials_batched", lambda: ials_batched_seconds(domain, agent, 30 * steps, s, predictor, batch)),
                ("gs_all", lambda: gs_seconds(domain, None, steps, s)),
                ("ials_parallel", lambda: parallel_env_seconds(domain, steps, s, aips)),
                ("ials_dials", lambda: multi_agent_seconds(domain, steps, s, aips, copies)),
                ("learner", lambda: learner_seconds(domain, copies, s)),
                ("learner_previous", lambda: learner_seconds(domain, copies, s, settings=PREVIOUS_PPO_SETTINGS)),
            ):
                bar.set_postfix_str(key)
                value = fn()
                if key.startswith("learner"):
                    suffix = key[len("learner"):]
                    runs["act" + suffix].append(value[0])
                    runs["update" + suffix].append(value[1])
                else:
                    runs[key].append(value)
                bar.update(1)
    v = {k: np.asarray(x) for k, x in runs.items()}
    gs_all_agent = v["gs_all"] / len(agents)  # seconds per agent-step with every agent learning
    return {
        "domain": env_id, "agent": agent, "agents": len(agents), "steps": steps, "batch": batch, "copies": copies,
        "predictor": predictor, "repeats": repeats,
        "single_agent": {
            "gs_steps_per_s": summary(1 / v["gs_one"]), "ials_steps_per_s": summary(1 / v["ials_one"]),
            "ials_batched_agent_steps_per_s": summary(1 / v["ials_batched"]),
            "ials_vs_gs_speed": summary(v["gs_one"] / v["ials_one"]),
            "ials_batched_vs_gs_speed": summary(v["gs_one"] / v["ials_batched"])},
        "every_agent": {
            "gs_us_per_agent_step": summary(gs_all_agent * 1e6),
            "ials_parallel_env_us_per_agent_step": summary(v["ials_parallel"] * 1e6),
            "ials_dials_us_per_agent_step": summary(v["ials_dials"] * 1e6),
            "ials_parallel_env_cost_vs_gs": summary(v["ials_parallel"] / gs_all_agent),
            "ials_dials_cost_vs_gs": summary(v["ials_dials"] / gs_all_agent)},
        "learner": {"act_us_per_agent_step": summary(v["act"] * 1e6),
                    "update_us_per_agent_sample": summary(v["update"] * 1e6),
                    "previous_settings": {"act_us_per_agent_step": summary(v["act_previous"] * 1e6),
                                          "update_us_per_agent_sample": summary(v["update_previous"] * 1e6)},
                    "update_cost_vs_previous": summary(v["update"] / v["update_previous"])},
    }


def bench_scaling(domain: Domain, steps: int | None, seed: int) -> list[dict]:
    """Per size: GS time per step; IALS time per agent-step, single and batched (DIALS).

    The IALS uses the ``"uniform"`` predictor (the domain's fixed class probabilities; in
    traffic 0.1 per lane, the GS's own inflow rate), so the local simulators carry realistic
    load at every size without training an AIP per size; the AIP network's own cost is in
    the default ``ials-zoo bench`` table.
    """
    env_id = domain.env_id
    if bench_of(domain).scaling is None:
        return []
    key, sizes = bench_of(domain).scaling
    rows = []
    for size in sizes:
        options = {key: size}
        agents = domain.possible_agents(**options)
        agent = agents[len(agents) // 2]
        n_steps = steps or domain.episode_length
        print(f"[{env_id}] {key}={size}: GS with {len(agents)} agents ...", flush=True)
        gs = 1 / gs_seconds(domain, [agent], n_steps, seed, **options)
        print(f"[{env_id}] {key}={size}: IALS single and x{len(agents)} ...", flush=True)
        single = 1 / ials_seconds(domain, agent, 3 * n_steps, seed, "uniform", **options)
        # DIALS: one local simulator per agent; every region of a domain has the same
        # layout, so one batch of len(agents) copies costs what all agents' IALS steps cost.
        batched = 1 / ials_batched_seconds(domain, agent, 10 * n_steps * len(agents) // 4, seed, "uniform",
                                            len(agents), **options)
        rows.append({
            "domain": env_id, "size": list(size), "agents": len(agents),
            "gs_steps_per_s": gs, "gs_agent_steps_per_s": gs * len(agents),
            "ials_single_steps_per_s": single, "ials_agent_steps_per_s": batched,
            "gs_us_per_step": 1e6 / gs, "ials_single_us_per_step": 1e6 / single,
            "ials_us_per_agent_step": 1e6 / batched,
        })
    return rows


def bench_ppo(domain: Domain, steps: int, predictor: str, seed: int) -> list[dict]:
    """``ppo_single`` steps/s on the GS, the IALS and no simulator, with the time per step of
    each relative to the GS (the last one is the floor no simulator can beat)."""

    env_id = domain.env_id
    agent = domain.default_agents[0]
    simulator = "ials" if predictor == "trained" else predictor
    rows = [ppo_throughput(env_id, agent, sim, steps=steps, seed=seed) for sim in ("gs", simulator, NO_SIMULATOR)]
    rel = ppo_bound(rows)["time_per_step_vs_gs"]
    for r in rows:
        r["time_per_step_vs_gs"] = rel[r["simulator"]]
    return rows


def bench_versus(domain: Domain, steps: int | None, predictor, other: str, seed: int, repeats: int) -> dict:
    """Cost per agent-step of the multi-agent IALS with two AIP sets (``predictor`` and the file
    ``other``), interleaved with the GS in one run: the ParallelEnv users call and DIALS's
    batched core (16 copies). Prints and returns the medians and the ratios."""
    env_id = domain.env_id
    agents = domain.agents()
    steps = int(steps or 10 * domain.episode_length)
    sets = {"base": dict(zip(agents, resolve_predictor_set(predictor, env_id, agents, seed=seed))),
            "versus": dict(zip(agents, resolve_predictor_set(other, env_id, agents, seed=seed)))}
    times = {k: [] for k in ("gs", "env_base", "env_versus", "core_base", "core_versus")}
    for r in range(repeats):
        times["gs"].append(gs_seconds(domain, agents, steps, seed + r) / len(agents))
        for name, aips in sets.items():
            times[f"env_{name}"].append(parallel_env_seconds(domain, steps, seed + r, aips))
            times[f"core_{name}"].append(multi_agent_seconds(domain, max(1, steps // 10), seed + r, aips, 16))
    row = {"domain": env_id, "predictor": str(predictor), "versus": other, "repeats": repeats,
           **{k: summary(1e6 * np.asarray(v)) for k, v in times.items()}}
    print(f"\n[{env_id}] us per agent-step, median [min, max] of {repeats}: base = {predictor}, versus = {other}")
    for k in times:
        print(f"  {k:<12}{fmt(row[k], ',.2f')}")
    gs = row["gs"]["median"]
    print(f"  ParallelEnv / GS: base {row['env_base']['median'] / gs:.2f}, versus {row['env_versus']['median'] / gs:.2f}; "
          f"versus / base: ParallelEnv {row['env_versus']['median'] / row['env_base']['median']:.2f}, "
          f"DIALS core {row['core_versus']['median'] / row['core_base']['median']:.2f}", flush=True)
    return row


def bench_aip_archs(domain: Domain, steps: int | None, archs: list, seed: int, repeats: int) -> dict:
    """Cost per agent-step of the multi-agent IALS ParallelEnv with every agent's AIP of each
    architecture in ``archs`` (``parse_aip_archs``), interleaved with the GS in one run. Prints
    and returns the medians [min, max] and the cost vs the GS. The AIPs are untrained: their
    network costs what a trained one does, but a local simulator whose cost follows the
    influence it is given (SUMO: the vehicles inserted) runs at untrained arrival rates."""
    env_id = domain.env_id
    agents = domain.agents()
    steps = int(steps or 10 * domain.episode_length)
    sets = {f"{arch}-{hidden}{'-ar' if ar else ''}": {
        a: untrained_predictor(domain.region_spec(a), arch=arch, hidden=hidden, autoregressive=ar, seed=seed)
        for a in agents} for arch, hidden, ar in archs}
    times = {"gs": [], **{name: [] for name in sets}}
    for r in range(repeats):
        times["gs"].append(gs_seconds(domain, agents, steps, seed + r) / len(agents))
        for name, aips in sets.items():
            times[name].append(parallel_env_seconds(domain, steps, seed + r, aips))
    row = {"domain": env_id, "repeats": repeats, **{k: summary(1e6 * np.asarray(v)) for k, v in times.items()}}
    gs = row["gs"]["median"]
    print(f"\n[{env_id}] ParallelEnv µs per agent-step by AIP architecture, median [min, max] of {repeats}")
    for name in times:
        cost = "" if name == "gs" else f"   cost vs GS {row[name]['median'] / gs:.2f}"
        print(f"  {name:<12}{fmt(row[name], ',.2f')}{cost}", flush=True)
    return row


