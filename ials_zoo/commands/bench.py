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
import time

import numpy as np

import ials_zoo
from ials_zoo.baselines import dials
from ials_zoo.baselines.multiagent import PREVIOUS_PPO_SETTINGS, fill_update_size, frame_stack_of, ppo_config
from ials_zoo.baselines.throughput import NO_SIMULATOR, ppo_bound, ppo_throughput
from ials_zoo.commands import CommandError
from ials_zoo.core.domains import domain_ids, get_domain, ials_domain_ids
from ials_zoo.core.extras import bench_of, dials_of
from ials_zoo.influence.ials import make_ials, make_ials_vec_env
from ials_zoo.influence.multi import make_ials_parallel_env, make_multi_agent_ials, resolve_predictor_set
from ials_zoo.influence.networks import untrained_predictor
from ials_zoo.leaderboard import hardware_info
from ials_zoo.learners.batched_ppo import BatchedPPO, PPOConfig
from ials_zoo.utils import atomic_path, atomic_write_text


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


def machine_info() -> dict:
    """What the numbers were measured on: the leaderboard's ``hardware`` record
    (:func:`ials_zoo.leaderboard.hardware_info`) plus SUMO, torch's threads and the date."""
    import torch

    hardware = hardware_info()
    try:
        from importlib.metadata import version

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


# ------------------------------------------------------------------------------ timings
# each returns seconds per unit (per GS step, per agent-step, per sample)


def _gs_seconds(env_id: str, learners, steps: int, seed: int, **options) -> float:
    """Seconds per GS step with uniformly random actions for ``learners`` (others scripted)."""
    env = get_domain(env_id).parallel_env(learners=learners, **options)
    try:
        rng = np.random.default_rng(seed)
        env.reset(seed=seed)
        n = int(env.action_space(env.possible_agents[0]).n)
        done, t0 = 0, time.perf_counter()
        while done < steps:
            if not env.agents:
                env.reset(seed=int(rng.integers(2**31)))
            acts = rng.integers(n, size=len(env.agents))
            env.step({a: int(u) for a, u in zip(env.agents, acts)})
            done += 1
        return (time.perf_counter() - t0) / steps
    finally:
        env.close()


def _ials_seconds(env_id: str, agent: str, steps: int, seed: int, predictor, **options) -> float:
    """Seconds per step of one agent's IALS (Gymnasium API)."""

    env = make_ials(env_id, agent, predictor=predictor, seed=seed, **options)
    try:
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        acts = rng.integers(int(env.action_space.n), size=steps)
        t0 = time.perf_counter()
        for a in acts:
            _, _, terminated, truncated, _ = env.step(int(a))
            if terminated or truncated:
                env.reset()
        return (time.perf_counter() - t0) / steps
    finally:
        env.close()


def _ials_batched_seconds(env_id: str, agent: str, steps: int, seed: int, predictor, n_envs: int,
                          **options) -> float:
    """Seconds per agent-step of ``n_envs`` copies of one agent's IALS stepped together."""

    venv = make_ials_vec_env(env_id, agent, n_envs=n_envs, predictor=predictor, seed=seed, **options)
    try:
        venv.reset()
        rng = np.random.default_rng(seed)
        rounds = max(1, steps // n_envs)
        acts = rng.integers(int(venv.action_space.n), size=(rounds, n_envs))
        t0 = time.perf_counter()
        for a in acts:
            venv.step(a)
        return (time.perf_counter() - t0) / (rounds * n_envs)
    finally:
        venv.close()


def _parallel_env_seconds(env_id: str, steps: int, seed: int, predictors) -> float:
    """Seconds per agent-step of the multi-agent IALS as a PettingZoo ParallelEnv."""

    env = make_ials_parallel_env(env_id, None, predictor=predictors, seed=seed)
    try:
        rng = np.random.default_rng(seed)
        env.reset(seed=seed)
        agents = list(env.possible_agents)
        n = int(env.action_space(agents[0]).n)
        acts = rng.integers(n, size=(steps, len(agents)))
        t0 = time.perf_counter()
        for a in acts:
            if not env.agents:
                env.reset()
            env.step(dict(zip(agents, a.tolist())))
        return (time.perf_counter() - t0) / (steps * len(agents))
    finally:
        env.close()


def _multi_agent_seconds(env_id: str, steps: int, seed: int, predictors, copies: int) -> float:
    """Seconds per agent-step of every agent's IALS x ``copies``, stepped as DIALS does."""

    core = make_multi_agent_ials(env_id, None, copies, predictors, seed=seed)
    try:
        rng = np.random.default_rng(seed)
        core.reset(seed)
        A = len(core.agents)
        n = int(core.ls.action_space.n)
        rounds = max(1, steps // copies)
        acts = rng.integers(n, size=(rounds, A, copies))
        t0 = time.perf_counter()
        for a in acts:
            if core.t >= core.max_cycles:
                core.reset()
            core.step(a)
        return (time.perf_counter() - t0) / (rounds * A * copies)
    finally:
        core.close()


def _learner_seconds(env_id: str, copies: int, seed: int, updates: int = 5,
                     settings: dict | None = None) -> tuple[float, float]:
    """(seconds per agent-step of action selection, per agent-sample of a PPO update) of the
    batched learner of every agent, at the multi-agent baselines' settings (default) or at
    ``settings`` (e.g. :data:`~ials_zoo.baselines.multiagent.PREVIOUS_PPO_SETTINGS`)."""
    import torch


    domain = get_domain(env_id)
    agents = domain.agents()
    args = dials.Args(env_id=env_id, **(settings or {}))
    fill_update_size(args, domain)
    cfg = PPOConfig(**ppo_config(args, copies, frame_stack_of(args, domain)))
    width = int(np.prod(domain.observation_space.shape)) * frame_stack_of(args, domain)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        learner = BatchedPPO(agents, width, domain.n_actions, cfg, seed=seed, total_updates=updates + 1)
        rng = np.random.default_rng(seed)
        A, N = len(agents), cfg.n_steps * cfg.n_envs
        obs = rng.random((A, copies, width), dtype=np.float32)
        rounds = max(20, 2000 // (A * copies))
        learner.act(obs)
        t0 = time.perf_counter()
        for _ in range(rounds):
            learner.act(obs)
        act = (time.perf_counter() - t0) / (rounds * A * copies)
        batch = (rng.random((A, N, width), dtype=np.float32), rng.integers(domain.n_actions, size=(A, N)),
                 np.full((A, N), -np.log(domain.n_actions)), rng.standard_normal((A, N)),
                 rng.standard_normal((A, N)), rng.standard_normal((A, N)))
        learner.update(*batch)
        t0 = time.perf_counter()
        for _ in range(updates):
            learner.update(*batch)
        update = (time.perf_counter() - t0) / (updates * A * N)
        return act, update
    finally:
        torch.set_num_threads(threads)


def bench_domain(env_id: str, steps: int | None, batch: int, predictor, seed: int, repeats: int) -> dict:
    """Every measurement of one domain, ``repeats`` times (module docstring)."""

    domain = get_domain(env_id)
    agent = domain.default_agents[0]
    agents = domain.agents()
    # 10 episodes per measurement: shorter ones swung several-fold on a shared machine
    steps = steps or 10 * domain.episode_length
    copies = dials_of(domain).copies
    print(f"[{env_id}] preparing the AIPs of {len(agents)} agents ({predictor}) ...", flush=True)
    aips = dict(zip(agents, resolve_predictor_set(predictor, env_id, agents, seed=seed)))
    runs: dict[str, list] = {k: [] for k in ("gs_one", "ials_one", "ials_batched", "gs_all", "ials_parallel",
                                             "ials_dials", "act", "update", "act_previous", "update_previous")}
    from tqdm.auto import tqdm

    with tqdm(total=repeats * 8, desc=f"bench {env_id}", unit="measurement") as bar:
        for r in range(repeats):
            s = seed + r
            for key, fn in (
                ("gs_one", lambda: _gs_seconds(env_id, [agent], steps, s)),
                ("ials_one", lambda: _ials_seconds(env_id, agent, 3 * steps, s, predictor)),
                ("ials_batched", lambda: _ials_batched_seconds(env_id, agent, 30 * steps, s, predictor, batch)),
                ("gs_all", lambda: _gs_seconds(env_id, None, steps, s)),
                ("ials_parallel", lambda: _parallel_env_seconds(env_id, steps, s, aips)),
                ("ials_dials", lambda: _multi_agent_seconds(env_id, steps, s, aips, copies)),
                ("learner", lambda: _learner_seconds(env_id, copies, s)),
                ("learner_previous", lambda: _learner_seconds(env_id, copies, s, settings=PREVIOUS_PPO_SETTINGS)),
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


def _fmt(s: dict, spec: str = ",.0f", suffix: str = "") -> str:
    return f"{format(s['median'], spec)}{suffix} [{format(s['min'], spec)}, {format(s['max'], spec)}]"


def _print_domain(row: dict) -> None:
    sa, ea, ln = row["single_agent"], row["every_agent"], row["learner"]
    print(f"\n{row['domain']} ({row['agents']} agents; median [min, max] of {row['repeats']} runs; AIPs: "
          f"{row['predictor']})")
    print(f"  one learner ({row['agent']}), steps/s:")
    print(f"    GS                        {_fmt(sa['gs_steps_per_s'])}")
    print(f"    IALS                      {_fmt(sa['ials_steps_per_s'])}   speed vs GS "
          f"{_fmt(sa['ials_vs_gs_speed'], '.1f', 'x')}")
    print(f"    IALS x{row['batch']:<3} batched (agent-steps/s) {_fmt(sa['ials_batched_agent_steps_per_s'])}   "
          f"speed vs GS {_fmt(sa['ials_batched_vs_gs_speed'], '.1f', 'x')}")
    print("  every agent learning, µs per agent-step (cost vs GS: < 1 is cheaper):")
    print(f"    GS, every agent acting    {_fmt(ea['gs_us_per_agent_step'], '.2f')}")
    print(f"    IALS ParallelEnv          {_fmt(ea['ials_parallel_env_us_per_agent_step'], '.2f')}   cost vs GS "
          f"{_fmt(ea['ials_parallel_env_cost_vs_gs'], '.2f')}")
    print(f"    IALS as DIALS steps it    {_fmt(ea['ials_dials_us_per_agent_step'], '.2f')}   cost vs GS "
          f"{_fmt(ea['ials_dials_cost_vs_gs'], '.2f')}   ({row['copies']} copies per agent)")
    print("  the batched PPO learner of every agent:")
    print(f"    act, µs per agent-step    {_fmt(ln['act_us_per_agent_step'], '.2f')}")
    print(f"    update, µs per sample     {_fmt(ln['update_us_per_agent_sample'], '.2f')}   "
          f"vs previous settings {_fmt(ln['update_cost_vs_previous'], '.2f', 'x')} "
          f"({_fmt(ln['previous_settings']['update_us_per_agent_sample'], '.2f')} µs)")
    for line in conclusion(row):
        print(line)


def conclusion(row: dict) -> list[str]:
    """What to take from a domain's figures, in words (the figures' medians)."""
    sa, ea, ln = row["single_agent"], row["every_agent"], row["learner"]
    env_cost = ea["ials_parallel_env_cost_vs_gs"]["median"]
    array_cost = ea["ials_dials_cost_vs_gs"]["median"]
    faster = "cheaper than" if array_cost < 1 else "dearer than"
    lines = [
        "  what to take from it (GS: the global simulator, the whole system; IALS: one agent's local simulator, "
        "its region only, plus its AIP, the network that predicts what comes in from outside):",
        f"    - one learner among scripted neighbours: its IALS steps {sa['ials_vs_gs_speed']['median']:.1f}x as fast "
        f"as the GS, {sa['ials_batched_vs_gs_speed']['median']:.1f}x batched ({row['batch']} copies in one array).",
        f"    - every agent learning: the array API (MultiAgentIALS, arrays [agents, copies, ...], what DIALS steps) "
        f"costs {array_cost:.2f}x the GS per agent-step, {faster} it; the dict ParallelEnv costs {env_cost:.2f}x"
        + (": it steps one copy and builds per-agent dicts every step, so it is the compatible API, not the fast one."
           if env_cost > 1.2 * array_cost else
           ", about the same here: the simulator's own step dominates both."),
        "    - 'cost vs GS' is computed within each repeat (IALS and GS timed back to back) and its median shown, so "
        "it need not equal the ratio of the two medians beside it (machines swing 2-4x between repeats).",
        f"    - 'vs previous settings': the PPO update at the multi-agent baselines' settings against the settings "
        f"before the ablation (3 epochs of 128 samples, docs/ablation.md): {ln['update_cost_vs_previous']['median']:.2f}x "
        "per sample.",
    ]
    return lines



def verdict(rows: list[dict]) -> list[str]:
    """One line across the domains measured: where the IALS pays and where it does not."""
    parts = [f"{r['domain']} {r['single_agent']['ials_vs_gs_speed']['median']:.1f}x as fast for one learner, "
             f"{r['every_agent']['ials_dials_cost_vs_gs']['median']:.2f}x the GS's cost with every agent learning"
             for r in rows]
    pays = [r["domain"] for r in rows if r["every_agent"]["ials_dials_cost_vs_gs"]["median"] < 1]
    return ["\nacross domains: the IALS is " + "; ".join(parts) + ".",
            f"  every agent learning on the IALS pays (costs less than the GS) in: {', '.join(pays) or 'none'} on this "
            "machine. A network's lights (sumo_net_v0) are measured apart: ials-zoo bench --domain sumo_net_v0."]


def bench_scaling(env_id: str, steps: int | None, seed: int) -> list[dict]:
    """Per size: GS time per step; IALS time per agent-step, single and batched (DIALS).

    The IALS uses the ``"uniform"`` predictor (the domain's fixed class probabilities; in
    traffic 0.1 per lane, the GS's own inflow rate), so the local simulators carry realistic
    load at every size without training an AIP per size; the AIP network's own cost is in
    the default ``ials-zoo bench`` table.
    """
    domain = get_domain(env_id)
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
        gs = 1 / _gs_seconds(env_id, [agent], n_steps, seed, **options)
        print(f"[{env_id}] {key}={size}: IALS single and x{len(agents)} ...", flush=True)
        single = 1 / _ials_seconds(env_id, agent, 3 * n_steps, seed, "uniform", **options)
        # DIALS: one local simulator per agent; every region of a domain has the same
        # layout, so one batch of len(agents) copies costs what all agents' IALS steps cost.
        batched = 1 / _ials_batched_seconds(env_id, agent, 10 * n_steps * len(agents) // 4, seed, "uniform",
                                            len(agents), **options)
        rows.append({
            "domain": env_id, "size": list(size), "agents": len(agents),
            "gs_steps_per_s": gs, "gs_agent_steps_per_s": gs * len(agents),
            "ials_single_steps_per_s": single, "ials_agent_steps_per_s": batched,
            "gs_us_per_step": 1e6 / gs, "ials_single_us_per_step": 1e6 / single,
            "ials_us_per_agent_step": 1e6 / batched,
        })
    return rows


def _plot_scaling(rows: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    domains = sorted({r["domain"] for r in rows})
    fig, axes = plt.subplots(1, max(len(domains), 1), figsize=(5 * max(len(domains), 1), 4), squeeze=False)
    axes = axes[0]
    for ax, env_id in zip(axes, domains):
        sel = [r for r in rows if r["domain"] == env_id]
        if not sel:
            ax.set_visible(False)
            continue
        n = [r["agents"] for r in sel]
        ax.plot(n, [r["gs_us_per_step"] for r in sel], "o-", label="GS: one step (all agents)")
        ax.plot(n, [r["ials_single_us_per_step"] for r in sel], "s-",
                label="IALS single: one agent-step")
        ax.plot(n, [r["ials_us_per_agent_step"] for r in sel], "^-",
                label="IALS batched over all agents: one agent-step")
        ax.set_xlabel("agents")
        ax.set_ylabel("µs")
        ax.set_yscale("log")
        ax.set_title(env_id)
        ax.grid(True, alpha=0.3)
        ax.legend()
    fig.suptitle("Cost of one step of experience for one agent: GS vs IALS")
    fig.tight_layout()

    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def bench_ppo(env_id: str, steps: int, predictor: str, seed: int) -> list[dict]:
    """``ppo_single`` steps/s on the GS, the IALS and no simulator, with the time per step of
    each relative to the GS (the last one is the floor no simulator can beat)."""

    agent = get_domain(env_id).default_agents[0]
    simulator = "ials" if predictor == "trained" else predictor
    rows = [ppo_throughput(env_id, agent, sim, steps=steps, seed=seed) for sim in ("gs", simulator, NO_SIMULATOR)]
    rel = ppo_bound(rows)["time_per_step_vs_gs"]
    for r in rows:
        r["time_per_step_vs_gs"] = rel[r["simulator"]]
    return rows


def bench_versus(env_id: str, steps: int | None, predictor, other: str, seed: int, repeats: int) -> dict:
    """Cost per agent-step of the multi-agent IALS with two AIP sets (``predictor`` and the file
    ``other``), interleaved with the GS in one run: the ParallelEnv users call and DIALS's
    batched core (16 copies). Prints and returns the medians and the ratios."""
    domain = get_domain(env_id)
    agents = domain.agents()
    steps = int(steps or 10 * domain.episode_length)
    sets = {"base": dict(zip(agents, resolve_predictor_set(predictor, env_id, agents, seed=seed))),
            "versus": dict(zip(agents, resolve_predictor_set(other, env_id, agents, seed=seed)))}
    times = {k: [] for k in ("gs", "env_base", "env_versus", "core_base", "core_versus")}
    for r in range(repeats):
        times["gs"].append(_gs_seconds(env_id, agents, steps, seed + r) / len(agents))
        for name, aips in sets.items():
            times[f"env_{name}"].append(_parallel_env_seconds(env_id, steps, seed + r, aips))
            times[f"core_{name}"].append(_multi_agent_seconds(env_id, max(1, steps // 10), seed + r, aips, 16))
    row = {"domain": env_id, "predictor": str(predictor), "versus": other, "repeats": repeats,
           **{k: summary(1e6 * np.asarray(v)) for k, v in times.items()}}
    print(f"\n[{env_id}] us per agent-step, median [min, max] of {repeats}: base = {predictor}, versus = {other}")
    for k in times:
        print(f"  {k:<12}{_fmt(row[k], ',.2f')}")
    gs = row["gs"]["median"]
    print(f"  ParallelEnv / GS: base {row['env_base']['median'] / gs:.2f}, versus {row['env_versus']['median'] / gs:.2f}; "
          f"versus / base: ParallelEnv {row['env_versus']['median'] / row['env_base']['median']:.2f}, "
          f"DIALS core {row['core_versus']['median'] / row['core_base']['median']:.2f}", flush=True)
    return row


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


def bench_aip_archs(env_id: str, steps: int | None, archs: list, seed: int, repeats: int) -> dict:
    """Cost per agent-step of the multi-agent IALS ParallelEnv with every agent's AIP of each
    architecture in ``archs`` (``parse_aip_archs``), interleaved with the GS in one run. Prints
    and returns the medians [min, max] and the cost vs the GS. The AIPs are untrained: their
    network costs what a trained one does, but a local simulator whose cost follows the
    influence it is given (SUMO: the vehicles inserted) runs at untrained arrival rates."""
    domain = get_domain(env_id)
    agents = domain.agents()
    steps = int(steps or 10 * domain.episode_length)
    sets = {f"{arch}-{hidden}{'-ar' if ar else ''}": {
        a: untrained_predictor(domain.region_spec(a), arch=arch, hidden=hidden, autoregressive=ar, seed=seed)
        for a in agents} for arch, hidden, ar in archs}
    times = {"gs": [], **{name: [] for name in sets}}
    for r in range(repeats):
        times["gs"].append(_gs_seconds(env_id, agents, steps, seed + r) / len(agents))
        for name, aips in sets.items():
            times[name].append(_parallel_env_seconds(env_id, steps, seed + r, aips))
    row = {"domain": env_id, "repeats": repeats, **{k: summary(1e6 * np.asarray(v)) for k, v in times.items()}}
    gs = row["gs"]["median"]
    print(f"\n[{env_id}] ParallelEnv µs per agent-step by AIP architecture, median [min, max] of {repeats}")
    for name in times:
        cost = "" if name == "gs" else f"   cost vs GS {row[name]['median'] / gs:.2f}"
        print(f"  {name:<12}{_fmt(row[name], ',.2f')}{cost}", flush=True)
    return row


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
    gs_only = args.domain != "all" and not get_domain(args.domain).has_ials
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
        rows = [r for env_id in env_ids for r in bench_ppo(env_id, args.ppo_steps, args.predictor, args.seed)]
        print(f"\nppo_single training throughput ({args.ppo_steps} steps each, 8 envs, evaluation excluded)")
        print(f"{'domain':<16}{'simulator':<12}{'PPO steps/s':>12}{'time/step vs GS':>17}")
        for r in rows:
            print(f"{r['domain']:<16}{r['simulator']:<12}{r['steps_per_s']:>12,.0f}{r['time_per_step_vs_gs']:>17.2f}")
        print("'none' is PPO alone (a simulator that costs nothing): no IALS can train in less than that "
              "share of the GS's wall-clock.")
    elif archs:
        rows = [bench_aip_archs(env_id, args.steps, archs, args.seed, args.repeats) for env_id in env_ids]
    elif args.versus:
        if not os.path.isfile(args.versus):
            raise CommandError(f"--versus {args.versus!r}: no such AIP set file")
        rows = [bench_versus(env_id, args.steps, args.predictor, args.versus, args.seed, args.repeats)
                for env_id in env_ids]
    elif args.scaling:
        rows = [r for env_id in env_ids for r in bench_scaling(env_id, args.steps, args.seed)]
        print(f"\n{'domain':<16}{'size':>9}{'agents':>8}{'GS steps/s':>12}"
              f"{'GS µs/step':>12}{'IALS single µs':>16}{'IALS batched µs/agent':>23}")
        for r in rows:
            print(f"{r['domain']:<16}{'x'.join(map(str, r['size'])):>9}{r['agents']:>8}"
                  f"{r['gs_steps_per_s']:>12,.0f}{r['gs_us_per_step']:>12,.0f}"
                  f"{r['ials_single_us_per_step']:>16,.1f}{r['ials_us_per_agent_step']:>23,.1f}")
        _plot_scaling(rows, args.plot)
        print(f"plot: {args.plot}")
    else:
        rows = []
        for env_id in env_ids:
            rows.append(bench_domain(env_id, args.steps, args.batch, args.predictor, args.seed, args.repeats))
            _print_domain(rows[-1])
        if len(rows) > 1:
            for line in verdict(rows):
                print(line)
    if args.out:
        atomic_write_text(args.out, json.dumps({"machine": machine, "rows": rows}, indent=2) + "\n")
        print(f"figures written to {args.out}")
    return 0
