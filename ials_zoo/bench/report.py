"""The bench's figures in words: a domain's table, what to take from it, a verdict across
domains, and the plot of cost against the system's size."""

from __future__ import annotations

from ials_zoo.utils import atomic_path


def fmt(s: dict, spec: str = ",.0f", suffix: str = "") -> str:
    return f"{format(s['median'], spec)}{suffix} [{format(s['min'], spec)}, {format(s['max'], spec)}]"


def print_domain(row: dict) -> None:
    sa, ea, ln = row["single_agent"], row["every_agent"], row["learner"]
    print(f"\n{row['domain']} ({row['agents']} agents; median [min, max] of {row['repeats']} runs; AIPs: "
          f"{row['predictor']})")
    print(f"  one learner ({row['agent']}), steps/s:")
    print(f"    GS                        {fmt(sa['gs_steps_per_s'])}")
    print(f"    IALS                      {fmt(sa['ials_steps_per_s'])}   speed vs GS "
          f"{fmt(sa['ials_vs_gs_speed'], '.1f', 'x')}")
    print(f"    IALS x{row['batch']:<3} batched (agent-steps/s) {fmt(sa['ials_batched_agent_steps_per_s'])}   "
          f"speed vs GS {fmt(sa['ials_batched_vs_gs_speed'], '.1f', 'x')}")
    print("  every agent learning, µs per agent-step (cost vs GS: < 1 is cheaper):")
    print(f"    GS, every agent acting    {fmt(ea['gs_us_per_agent_step'], '.2f')}")
    print(f"    IALS ParallelEnv          {fmt(ea['ials_parallel_env_us_per_agent_step'], '.2f')}   cost vs GS "
          f"{fmt(ea['ials_parallel_env_cost_vs_gs'], '.2f')}")
    print(f"    IALS as DIALS steps it    {fmt(ea['ials_dials_us_per_agent_step'], '.2f')}   cost vs GS "
          f"{fmt(ea['ials_dials_cost_vs_gs'], '.2f')}   ({row['copies']} copies per agent)")
    print("  the batched PPO learner of every agent:")
    print(f"    act, µs per agent-step    {fmt(ln['act_us_per_agent_step'], '.2f')}")
    print(f"    update, µs per sample     {fmt(ln['update_us_per_agent_sample'], '.2f')}   "
          f"vs previous settings {fmt(ln['update_cost_vs_previous'], '.2f', 'x')} "
          f"({fmt(ln['previous_settings']['update_us_per_agent_sample'], '.2f')} µs)")
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


def plot_scaling(rows: list[dict], path: str) -> None:
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


