"""``ials-zoo bench``: measure global-simulator (GS) and IALS speed in one run.

For each domain it prints, on this machine, in one process:

* GS steps/s with one learner (the paper's setting: the others scripted) and with every agent
  learning (random actions);
* IALS steps/s for one agent (one local simulator + one AIP call per step);
* IALS agent-steps/s batched: ``--batch`` local simulators advanced together with one
  batched AIP call per step;
* the ratios IALS / GS.

``--ppo`` instead times the ``ppo_single`` baseline itself (its settings, 8 envs) on the GS,
the IALS and on no simulator at all (a vec env whose steps cost nothing): the last is PPO's
own cost, the floor under any IALS-vs-GS wall-clock ratio.

``--scaling`` instead grows the system (traffic 3x3..10x10, warehouse 4x4..10x10 robots) and
reports, per size, the GS time per step and per agent-step against the time per agent-step of
one batched IALS per agent (all agents' regions, as in DIALS), with a PNG plot.

Numbers are wall-clock on whatever else the machine is doing: run on an idle machine.
"""

from __future__ import annotations

import json
import time

import numpy as np

from ials_zoo.core.domains import domain_ids, get_domain
from ials_zoo.utils import atomic_write_text


def configure(parser):
    parser.add_argument("--domain", choices=["all", *domain_ids()], default="all")
    parser.add_argument("--steps", type=int, default=None,
                        help="GS steps per measurement (default: 3 episodes)")
    parser.add_argument("--batch", type=int, default=64,
                        help="local simulators in the batched IALS measurement")
    parser.add_argument("--predictor", default="trained",
                        help="AIP used by the IALS (trained, untrained, fixed:P, marginal, path)")
    parser.add_argument("--scaling", action="store_true",
                        help="measure GS vs IALS cost as the system grows, and plot it")
    parser.add_argument("--ppo", action="store_true",
                        help="time PPO training on the GS, the IALS and no simulator (PPO's own cost)")
    parser.add_argument("--ppo-steps", type=int, default=30_000, help="PPO steps per --ppo measurement")
    parser.add_argument("--out", default=None, help="write the figures as JSON here")
    parser.add_argument("--plot", default="bench_scaling.png",
                        help="PNG for --scaling (default: bench_scaling.png)")
    parser.add_argument("--seed", type=int, default=0)


def _timed_gs(env_id: str, learners, steps: int, seed: int, **options) -> float:
    """GS steps/s with uniformly random actions for ``learners`` (others scripted)."""
    domain = get_domain(env_id)
    env = domain.parallel_env(learners=learners, **options)
    try:
        rng = np.random.default_rng(seed)
        env.reset(seed=seed)
        for agent in env.possible_agents:
            env.action_space(agent).seed(int(rng.integers(2**31)))
        done, t0 = 0, time.perf_counter()
        while done < steps:
            if not env.agents:
                env.reset(seed=int(rng.integers(2**31)))
            env.step({a: env.action_space(a).sample() for a in env.agents})
            done += 1
        return steps / (time.perf_counter() - t0)
    finally:
        env.close()


def _timed_ials_single(env_id: str, agent: str, steps: int, seed: int, predictor,
                       **options) -> float:
    from ials_zoo.influence.ials import make_ials

    env = make_ials(env_id, agent, predictor=predictor, seed=seed, **options)
    try:
        env.reset(seed=seed)
        env.action_space.seed(seed)
        t0 = time.perf_counter()
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                env.reset()
        return steps / (time.perf_counter() - t0)
    finally:
        env.close()


def _timed_ials_batched(env_id: str, agent: str, steps: int, seed: int, predictor,
                        n_envs: int, **options) -> float:
    """Agent-steps/s of ``n_envs`` local simulators with one batched AIP call per step."""
    from ials_zoo.influence.ials import make_ials_vec_env

    venv = make_ials_vec_env(env_id, agent, n_envs=n_envs, predictor=predictor, seed=seed,
                             **options)
    try:
        venv.reset()
        rng = np.random.default_rng(seed)
        n_actions = venv.action_space.n
        rounds = max(1, steps // n_envs)
        t0 = time.perf_counter()
        for _ in range(rounds):
            venv.step(rng.integers(n_actions, size=n_envs))
        return rounds * n_envs / (time.perf_counter() - t0)
    finally:
        venv.close()


def bench_domain(env_id: str, steps: int | None, batch: int, predictor, seed: int) -> dict:
    domain = get_domain(env_id)
    agent = domain.default_agents[0]
    steps = steps or 3 * domain.episode_length
    row = {"domain": env_id, "agent": agent, "steps": steps, "batch": batch}
    print(f"[{env_id}] GS, one learner ({agent}) ...", flush=True)
    row["gs_one_learner"] = _timed_gs(env_id, [agent], steps, seed)
    print(f"[{env_id}] GS, every agent learning ...", flush=True)
    row["gs_all_learners"] = _timed_gs(env_id, None, steps, seed)
    print(f"[{env_id}] IALS single ...", flush=True)
    row["ials_single"] = _timed_ials_single(env_id, agent, 3 * steps, seed, predictor)
    print(f"[{env_id}] IALS batched x{batch} ...", flush=True)
    row["ials_batched"] = _timed_ials_batched(env_id, agent, 30 * steps, seed, predictor, batch)
    row["ratio_single"] = row["ials_single"] / row["gs_one_learner"]
    row["ratio_batched"] = row["ials_batched"] / row["gs_one_learner"]
    return row


def _print_table(rows: list[dict]) -> None:
    header = (f"{'domain':<16}{'GS 1 learner':>14}{'GS all':>10}{'IALS':>10}"
              f"{'IALS batched':>14}{'IALS/GS':>9}{'batched/GS':>12}")
    print("\nsteps/s (batched: agent-steps/s)")
    print(header)
    print("-" * len(header))
    for r in rows:
        print(f"{r['domain']:<16}{r['gs_one_learner']:>14,.0f}{r['gs_all_learners']:>10,.0f}"
              f"{r['ials_single']:>10,.0f}{r['ials_batched']:>14,.0f}"
              f"{r['ratio_single']:>8.1f}x{r['ratio_batched']:>11.1f}x")


def bench_scaling(env_id: str, steps: int | None, seed: int) -> list[dict]:
    """Per size: GS time per step; IALS time per agent-step, single and batched (DIALS).

    The IALS uses the ``"uniform"`` predictor (the domain's fixed class probabilities; in
    traffic 0.1 per lane, the GS's own inflow rate), so the local simulators carry realistic
    load at every size without training an AIP per size; the AIP network's own cost is in
    the default ``ials-zoo bench`` table.
    """
    domain = get_domain(env_id)
    if domain.scaling is None:
        return []
    key, sizes = domain.scaling
    rows = []
    for size in sizes:
        options = {key: size}
        agents = domain.possible_agents(**options)
        agent = agents[len(agents) // 2]
        n_steps = steps or domain.episode_length
        print(f"[{env_id}] {key}={size}: GS with {len(agents)} agents ...", flush=True)
        gs = _timed_gs(env_id, [agent], n_steps, seed, **options)
        print(f"[{env_id}] {key}={size}: IALS single and x{len(agents)} ...", flush=True)
        single = _timed_ials_single(env_id, agent, 3 * n_steps, seed, "uniform", **options)
        # DIALS: one local simulator per agent; every region of a domain has the same
        # layout, so one batch of len(agents) copies costs what all agents' IALS steps cost.
        batched = _timed_ials_batched(env_id, agent, 10 * n_steps * len(agents) // 4, seed,
                                      "uniform", len(agents), **options)
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
    from ials_zoo.utils import atomic_path

    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def bench_ppo(env_id: str, steps: int, predictor: str, seed: int) -> list[dict]:
    """``ppo_single`` steps/s on the GS, the IALS and no simulator, with the time per step of
    each relative to the GS (the last one is the floor no simulator can beat)."""
    from ials_zoo.baselines.throughput import NO_SIMULATOR, ppo_bound, ppo_throughput

    agent = get_domain(env_id).default_agents[0]
    simulator = "ials" if predictor == "trained" else predictor
    rows = [ppo_throughput(env_id, agent, sim, steps=steps, seed=seed) for sim in ("gs", simulator, NO_SIMULATOR)]
    rel = ppo_bound(rows)["time_per_step_vs_gs"]
    for r in rows:
        r["time_per_step_vs_gs"] = rel[r["simulator"]]
    return rows


def run(args) -> int:
    if args.steps is not None and args.steps < 1:
        raise SystemExit(f"--steps must be >= 1, got {args.steps}")
    if args.batch < 1:
        raise SystemExit(f"--batch must be >= 1, got {args.batch}")
    env_ids = domain_ids() if args.domain == "all" else [args.domain]
    if args.ppo:
        if args.ppo_steps < 1:
            raise SystemExit(f"--ppo-steps must be >= 1, got {args.ppo_steps}")
        rows = [r for env_id in env_ids for r in bench_ppo(env_id, args.ppo_steps, args.predictor, args.seed)]
        print(f"\nppo_single training throughput ({args.ppo_steps} steps each, 8 envs, evaluation excluded)")
        print(f"{'domain':<16}{'simulator':<12}{'PPO steps/s':>12}{'time/step vs GS':>17}")
        for r in rows:
            print(f"{r['domain']:<16}{r['simulator']:<12}{r['steps_per_s']:>12,.0f}{r['time_per_step_vs_gs']:>17.2f}")
        print("'none' is PPO alone (a simulator that costs nothing): no IALS can train in less than that "
              "share of the GS's wall-clock.")
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
        rows = [bench_domain(e, args.steps, args.batch, args.predictor, args.seed)
                for e in env_ids]
        _print_table(rows)
    if args.out:
        atomic_write_text(args.out, json.dumps(rows, indent=2) + "\n")
        print(f"figures written to {args.out}")
    return 0
