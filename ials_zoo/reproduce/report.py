"""Aggregation of a study: curves, tables, ``reproduction.md`` and leaderboard submissions.

Everything is re-made from the run folders (``job.json``, ``curve.json``, ``result.json``,
``report.json``, ``lifetimes.json``, ``dset.json``), so ``ials-zoo reproduce --report-only``
works on a partly finished study: missing runs are listed as missing, never guessed.

Curves: each seed's GS learning curve (mean return vs wall-clock seconds, AIP collection and
training included) is interpolated linearly onto a common grid over the span every seed
covers; the band is the 95% Student-t interval over seeds (none with one seed).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ials_zoo.evaluation import mean_ci
from ials_zoo.reproduce.plan import label_of
from ials_zoo.utils import atomic_path, atomic_write_text

# SPEC §4 (authors' plotting notebooks).
PAPER = {
    "traffic_grid_v0": {"gs_hours": 6.16, "ials_hours": 2.13, "collect_s": 104, "train_s": 36,
                        "ce_trained": 0.22, "ce_untrained": 0.78},
    "warehouse_v0": {"gs_hours": 13.1, "ials_hours": 3.9, "collect_s": 112, "train_s": 207,
                     "ce_trained": 0.362, "ce_untrained": 1.46},
}
TARGET_SCORE_RATIO = 0.95
TARGET_TIME_RATIO = 1 / 3
# A difference in cross-entropy increase below this (nats) is not called a difference.
CLEAR_CE_GAP = 0.02
# Rows of a train_predictor report besides "trained".
CE_ROWS = (("untrained", "untrained (randomly initialised network, the paper's)"),
           ("uniform", "uniform (fixed class probabilities)"),
           ("marginal", "marginal"))


def normalize_ce(ce: dict) -> dict:
    """Cross-entropy rows under today's names: reports written before the influence package
    renamed its rows called the random network "random-init" and the fixed probabilities
    "untrained"; now they are "untrained" and "uniform"."""
    if "random-init" in ce and "uniform" not in ce:
        ce = dict(ce)
        ce["uniform"] = ce.pop("untrained")
        ce["untrained"] = ce.pop("random-init")
    return ce


def _load(path: Path):
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


# --------------------------------------------------------------------------------------------
# Loading runs


def load_runs(out, experiment: str) -> list[dict]:
    """Every PPO run folder of ``experiment`` under ``out``: ``{job, curve, result, dir}``
    (``curve``/``result`` None while missing)."""
    runs = []
    for jf in sorted(Path(out, experiment).glob("*/*/job.json")):
        job = _load(jf)
        if not job or job.get("kind") != "ppo":
            continue
        d = jf.parent
        runs.append({"job": job, "dir": d, "curve": _load(d / "curve.json"), "result": _load(d / "result.json")})
    return runs


def group(runs, key) -> dict:
    out: dict = {}
    for r in runs:
        out.setdefault(key(r), []).append(r)
    return out


# --------------------------------------------------------------------------------------------
# Statistics


def aggregate_curves(curves: list[list[dict]], n: int = 50) -> dict | None:
    """Mean and 95% CI over seeds of GS return vs wall-clock seconds.

    ``curves``: per seed, the points (``wall_clock_seconds``, ``mean``) of its curve.json.
    Returns ``{"seconds", "mean", "ci_low", "ci_high", "seeds"}`` on a common grid over the
    span all seeds cover (a single point if they share one), or None without data."""
    curves = [sorted(c, key=lambda p: p["wall_clock_seconds"]) for c in curves if c]
    if not curves:
        return None
    lo = max(c[0]["wall_clock_seconds"] for c in curves)
    hi = min(c[-1]["wall_clock_seconds"] for c in curves)
    if hi <= lo:
        grid = np.array([hi])
    else:
        grid = np.linspace(lo, hi, n)
    ys = np.stack([np.interp(grid, [p["wall_clock_seconds"] for p in c], [p["mean"] for p in c])
                   for c in curves])
    stats = [mean_ci(ys[:, i]) for i in range(len(grid))]
    return {"seconds": grid.tolist(), "mean": [s[0] for s in stats], "ci_low": [s[1] for s in stats],
            "ci_high": [s[2] for s in stats], "seeds": len(curves)}


def time_to_reach(agg: dict | None, target: float) -> float | None:
    """First wall-clock second at which the mean curve reaches ``target`` (None: never)."""
    if agg is None:
        return None
    for t, m in zip(agg["seconds"], agg["mean"]):
        if m >= target:
            return float(t)
    return None


def summarize_training(runs: list[dict]) -> dict:
    """Per (env_id, agent): per simulator label, final GS scores over seeds, wall-clock,
    PPO throughput, the aggregated curve, and the comparisons with the GS."""
    out = {}
    for (env_id, agent), rs in sorted(group(runs, lambda r: (r["job"]["params"]["env_id"],
                                                            r["job"]["params"]["agent"])).items()):
        sims = {}
        for label, srs in group(rs, lambda r: r["job"]["label"]).items():
            done = [r for r in srs if r["result"]]
            finals = [r["result"]["score"]["mean"] for r in done]
            totals = [r["result"]["training"]["wall_clock_seconds"] + r["result"]["training"]["aip_seconds"]
                      for r in done]
            aip_s = [r["result"]["training"]["aip_seconds"] for r in done]
            steps_s = [r["result"]["training"]["env_steps"] / max(r["result"]["training"]["wall_clock_seconds"], 1e-9)
                       for r in done]
            m, lo, hi = mean_ci(finals) if finals else (None, None, None)
            sims[label] = {
                "planned": len(srs), "finished": len(done), "seeds": [r["job"]["params"]["seed"] for r in done],
                "final_mean": m, "final_ci_low": lo, "final_ci_high": hi, "final_per_seed": finals,
                "total_seconds": float(np.mean(totals)) if totals else None,
                "aip_seconds": float(np.mean(aip_s)) if aip_s else None,
                "ppo_steps_per_second": float(np.mean(steps_s)) if steps_s else None,
                "env_steps": int(np.mean([r["result"]["training"]["env_steps"] for r in done])) if done else None,
                "curve": aggregate_curves([r["curve"]["points"] for r in srs if r["curve"]]),
            }
        gs = sims.get("gs", {})
        # The target is 95% of the end of the GS's own mean curve (the same evaluation protocol
        # as the curves it is compared with), not of the final score over more episodes.
        target = None
        if gs.get("curve") and gs["curve"]["mean"][-1] > 0:
            target = TARGET_SCORE_RATIO * gs["curve"]["mean"][-1]
        t_gs = time_to_reach(gs.get("curve"), target) if target is not None else None
        for label, s in sims.items():
            s["score_ratio_to_gs"] = (s["final_mean"] / gs["final_mean"]
                                      if s["final_mean"] is not None and gs.get("final_mean") else None)
            s["seconds_to_95pct_gs"] = time_to_reach(s["curve"], target) if target is not None else None
            s["time_ratio_to_gs"] = (s["seconds_to_95pct_gs"] / t_gs
                                     if s["seconds_to_95pct_gs"] is not None and t_gs else None)
        out[(env_id, agent)] = {"simulators": dict(sorted(sims.items(), key=lambda kv: _sim_order(kv[0]))),
                                "target_95pct": target}
    return out


def _sim_order(label: str):
    from ials_zoo.reproduce.plan import KNOWN_SIMULATORS

    return (KNOWN_SIMULATORS.index(label) if label in KNOWN_SIMULATORS else len(KNOWN_SIMULATORS), label)


def paper_steps_per_second(env_id: str) -> dict:
    """PPO throughput implied by SPEC §4 (2M steps / reported hours)."""
    p = PAPER[env_id]
    return {"gs": 2e6 / (p["gs_hours"] * 3600), "ials": 2e6 / (p["ials_hours"] * 3600)}


def reference_scores(leaderboard, env_id: str, agent: str) -> dict:
    """Scores of the reference policies (entries without training) on the board."""
    from ials_zoo.leaderboard import load_entries

    refs = {}
    try:
        entries = load_entries(leaderboard)
    except (OSError, ValueError):
        return refs
    for _, d in entries:
        if d.get("env_id") == env_id and d.get("agent") == agent and d.get("training") is None:
            refs[d["algorithm"]] = d["score"]["mean"]
    return refs


# --------------------------------------------------------------------------------------------
# Figures


def _savefig(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt

    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return path


def plot_training(summary: dict, refs: dict, path, title: str) -> Path:
    """GS mean return vs wall-clock (log x), mean ± 95% CI over seeds, per simulator, with
    the reference policies as horizontal lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for label, s in summary["simulators"].items():
        c = s["curve"]
        if c is None:
            continue
        x = np.maximum(np.asarray(c["seconds"]), 1e-3)
        (line,) = ax.plot(x, c["mean"], marker="." if len(x) == 1 else None,
                          label=f"{label} ({c['seeds']} seed{'s' if c['seeds'] != 1 else ''})")
        ax.fill_between(x, c["ci_low"], c["ci_high"], color=line.get_color(), alpha=0.2)
    for i, (name, score) in enumerate(sorted(refs.items())):
        ax.axhline(score, color="gray", ls=("--", ":", "-.")[i % 3], lw=1, label=f"{name} (reference)")
    if summary.get("target_95pct") is not None:
        ax.axhline(summary["target_95pct"], color="k", lw=0.6, alpha=0.5, label="95% of the GS curve's end")
    ax.set_xscale("log")
    ax.set_xlabel("wall-clock seconds (AIP data collection + training included)")
    ax.set_ylabel("GS mean episodic return")
    ax.set_title(title)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    return _savefig(fig, Path(path))


# --------------------------------------------------------------------------------------------
# Text


def _f(x, nd=3, unit=""):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return f"{x:.{nd}f}{unit}"


def _ci(s):
    if s["final_mean"] is None:
        return "-"
    if s["finished"] < 2:
        return f"{s['final_mean']:.3f} (1 seed)"
    return f"{s['final_mean']:.3f} [{s['final_ci_low']:.3f}, {s['final_ci_high']:.3f}]"


def _verdict(ok: bool | None) -> str:
    return {True: "holds", False: "does not hold", None: "not measured"}[ok]


def training_section(key, summary, aip_report, refs, png_name, budget_note) -> list[str]:
    env_id, agent = key
    sims = summary["simulators"]
    L = [f"### {env_id} / {agent}", "", f"![learning curves]({png_name})", ""]
    L += ["| simulator | runs done | final GS score (mean [95% CI] over seeds) | / GS | total wall-clock (s) "
          "| of which AIP (s) | PPO steps/s | s to 95% of GS curve's end | / GS's |",
          "|---|---|---|---|---|---|---|---|---|"]
    for label, s in sims.items():
        L.append(f"| {label} | {s['finished']}/{s['planned']} | {_ci(s)} | {_f(s['score_ratio_to_gs'], 2)} "
                 f"| {_f(s['total_seconds'], 0)} | {_f(s['aip_seconds'], 0)} | {_f(s['ppo_steps_per_second'], 0)} "
                 f"| {_f(s['seconds_to_95pct_gs'], 0)} | {_f(s['time_ratio_to_gs'], 2)} |")
    if refs:
        L += ["", "Reference policies on the leaderboard: " +
              ", ".join(f"{k} {v:.3f}" for k, v in sorted(refs.items()))]
    paper = PAPER.get(env_id, {})
    L += [""]
    if aip_report:
        ce = normalize_ce(aip_report["cross_entropy"])
        L += ["AIP (trained once for this study, timed here):", "",
              "| | measured | paper (SPEC §4) |", "|---|---|---|",
              f"| data collection (s) | {_f(aip_report['dataset'].get('collect_seconds'), 1)} "
              f"({aip_report['dataset']['steps']} steps) | {paper.get('collect_s', '-')} |",
              f"| AIP training (s) | {_f(aip_report.get('train_seconds'), 1)} | {paper.get('train_s', '-')} |",
              f"| test CE trained | {_f(ce['trained']['test'])} | {paper.get('ce_trained', '-')} |"]
        for name, what in CE_ROWS:
            if name in ce:
                paper_v = paper.get("ce_untrained", "-") if name == "untrained" else "-"
                L.append(f"| test CE {what} | {_f(ce[name]['test'])} | {paper_v} |")
        L.append("")
    else:
        L += ["AIP: not trained yet (no report.json).", ""]
    # Claims, computed from the numbers above.
    ials, gs = sims.get("ials", {}), sims.get("gs", {})
    r = ials.get("score_ratio_to_gs")
    tr = ials.get("time_ratio_to_gs")
    n_seeds = min([v["finished"] for v in sims.values() if v["finished"]] or [0])
    L += ["Claims (computed from the table; `-` = not measured"
          + ("; with a single seed there is no confidence interval, so one noisy run decides" if n_seeds < 2 else "")
          + "):", ""]
    L.append(f"- IALS policy scores >= {TARGET_SCORE_RATIO:.0%} of the GS policy on the GS: ratio {_f(r, 2)} "
             f"-> {_verdict(None if r is None else r >= TARGET_SCORE_RATIO)}.")
    L.append(f"- IALS reaches 95% of the end of the GS's curve in <= 1/3 of the GS's wall-clock: "
             f"{_f(ials.get('seconds_to_95pct_gs'), 0)} s vs {_f(gs.get('seconds_to_95pct_gs'), 0)} s, ratio {_f(tr, 2)} "
             f"-> {_verdict(None if tr is None else tr <= TARGET_TIME_RATIO)}"
             + (" (the IALS never reached it within the budget)" if gs.get("seconds_to_95pct_gs") and
                ials.get("final_mean") is not None and ials.get("seconds_to_95pct_gs") is None else "") + ".")
    total_ratio = (ials["total_seconds"] / gs["total_seconds"]
                   if ials.get("total_seconds") and gs.get("total_seconds") else None)
    L.append(f"- the paper's own measure (its bar charts): total training wall-clock for the same step budget, "
             f"AIP included, IALS vs GS: {_f(ials.get('total_seconds'), 0)} s vs {_f(gs.get('total_seconds'), 0)} s, "
             f"ratio {_f(total_ratio, 2)} -> <= 1/3 {_verdict(None if total_ratio is None else total_ratio <= TARGET_TIME_RATIO)}"
             + ("" if total_ratio is None else f", <= 1/5 {_verdict(total_ratio <= 0.2)}") + ".")
    un = sims.get("untrained-ials", {})
    if un.get("final_mean") is not None and ials.get("final_mean") is not None:
        if min(un["finished"], ials["finished"]) < 2:
            answer = "undecided: a 95% CI needs >= 2 seeds"
        else:
            answer = "yes" if un["final_ci_high"] < ials["final_ci_low"] else "no"
        L.append(f"- untrained-IALS clearly worse than IALS (95% CIs over seeds disjoint): {un['final_mean']:.3f} vs "
                 f"{ials['final_mean']:.3f} -> {answer} (paper: yes in traffic).")
    fx = sims.get("fixed:0.1", {})
    if fx.get("score_ratio_to_gs") is not None:
        L.append(f"- F-IALS 0.1 close to the GS (>= {TARGET_SCORE_RATIO:.0%}): ratio {fx['score_ratio_to_gs']:.2f} -> "
                 f"{'yes' if fx['score_ratio_to_gs'] >= TARGET_SCORE_RATIO else 'no'} "
                 f"(paper: yes in traffic, no in the warehouse).")
    if aip_report:
        ce = normalize_ce(aip_report["cross_entropy"])
        L.append(f"- AIP test CE trained << untrained: {ce['trained']['test']:.3f} vs {ce['untrained']['test']:.3f} "
                 f"(ratio {ce['trained']['test'] / max(ce['untrained']['test'], 1e-12):.2f}; paper "
                 f"{paper.get('ce_trained', '-')} vs {paper.get('ce_untrained', '-')}).")
    if gs.get("ppo_steps_per_second") and ials.get("ppo_steps_per_second") and paper:
        ps = paper_steps_per_second(env_id)
        L.append(f"- PPO throughput IALS / GS here: {ials['ppo_steps_per_second'] / gs['ppo_steps_per_second']:.2f}x "
                 f"({ials['ppo_steps_per_second']:.0f} vs {gs['ppo_steps_per_second']:.0f} steps/s); paper, from its "
                 f"2M-step wall-clocks: {paper['gs_hours'] / paper['ials_hours']:.2f}x ({ps['ials']:.0f} vs "
                 f"{ps['gs']:.0f} steps/s). The wall-clock ratio the paper reports is bounded by this throughput "
                 "ratio plus the AIP's one-off cost.")
    L += ["", f"Differences from the paper to keep in mind: {budget_note}", ""]
    return L


def memory_section(out, leaderboard=None) -> list[str]:
    L = []
    runs = load_runs(out, "memory")
    for (env_id, agent), rs in sorted(group(runs, lambda r: (r["job"]["params"]["env_id"],
                                                            r["job"]["params"]["agent"])).items()):
        stats = {}
        L += [f"### Memory (paper §5.4): {env_id} / {agent}, item_lifetime=8", "",
              "| AIP | agent frame stack | runs done | final GS score (item_lifetime=8) |", "|---|---|---|---|"]
        for label, srs in sorted(group(rs, lambda r: r["job"]["label"]).items()):
            finals = [r["result"]["score"]["mean"] for r in srs if r["result"]]
            name, fs = label.split(" ")
            if finals:
                m, lo, hi = mean_ci(finals)
                score = f"{m:.3f}" + (f" [{lo:.3f}, {hi:.3f}]" if len(finals) > 1 else " (1 seed)")
            else:
                score = "-"
            L.append(f"| {name} | {fs[2:]} | {len(finals)}/{len(srs)} | {score} |")
            if len(finals) > 1:
                stats[(name, fs)] = mean_ci(finals)
        L.append("")
        budgets = sorted({r["job"]["params"]["total_timesteps"] for r in rs})
        L.append(f"PPO budget {', '.join(f'{b:,}' for b in budgets)} steps per run. The paper's claim: an agent "
                 "with memory (frame stack 8) needs the AIP with memory (M-IALS beats NM-IALS); an agent "
                 "without memory (frame stack 1) does as well on either. Computed from the table "
                 "(95% CIs over seeds):")
        L.append("")
        for fs, what in (("fs8", "agent with memory"), ("fs1", "agent without memory")):
            m, nm = stats.get(("M-IALS", fs)), stats.get(("NM-IALS", fs))
            if not (m and nm):
                L.append(f"- {what}: not measured (needs >= 2 seeds on both simulators).")
                continue
            disjoint = m[1] > nm[2] or nm[1] > m[2]
            L.append(f"- {what}: M-IALS {m[0]:.3f} vs NM-IALS {nm[0]:.3f} -> "
                     + ("CIs disjoint: " + ("M-IALS better" if m[0] > nm[0] else "NM-IALS better")
                        if disjoint else "CIs overlap: no clear difference") + ".")
        L.append("")
    for lf in sorted(Path(out, "memory").glob("*/lifetimes/lifetimes.json")):
        d = _load(lf)
        if not d:
            continue
        png = lf.parent / "lifetimes.png"
        figure = f"`{png}`"
        if leaderboard is not None and png.is_file():
            # the figure travels with reproduction.md (the run folders stay outside the repository)
            name = f"reproduction_lifetimes_{d['env_id']}__{d['agent']}.png"
            with atomic_path(Path(leaderboard) / name, suffix=".png") as tmp:
                Path(tmp).write_bytes(png.read_bytes())
            figure = f"![item lifetimes]({name})"
        L += [f"Item lifetimes in {d['agent']}'s region ({d['episodes']} episodes per simulator, uniform random "
              f"robot):", "", figure, "", "| simulator | items | mean lifetime | share living exactly 8 steps |",
              "|---|---|---|---|"]
        for k, s in d["summary"].items():
            L.append(f"| {k} | {s['items']} | {_f(s['mean'], 2)} | {_f(s['share_at_lifetime'], 2)} |")
        L.append("")
    return L


def _dset_table(title: str, d: dict) -> list[str]:
    ce = d["cross_entropy"]
    offs = list(d["off_policy_data"])
    L = [title, "",
         "| AIP input | CE on-policy (test) | " + " | ".join(f"CE off-policy: {k}" for k in offs) + " | "
         + " | ".join(f"increase: {k}" for k in offs) + " |",
         "|---|---|" + "---|" * (2 * len(offs))]
    for name, c in ce.items():
        L.append(f"| {name} | {c['on_policy']:.3f} | " + " | ".join(f"{c['off_policy'][k]:.3f}" for k in offs)
                 + " | " + " | ".join(f"{c['increase'][k]:+.3f}" for k in offs) + " |")
    L.append("")
    if "dset" in ce and "full" in ce:
        for k in offs:
            gap = ce["full"]["increase"][k] - ce["dset"]["increase"][k]
            if abs(gap) < CLEAR_CE_GAP:
                verdict = f"no clear difference (|gap| {abs(gap):.3f} < {CLEAR_CE_GAP} nats)"
            elif gap > 0:
                verdict = "the full-history AIP degrades more (consistent with spurious correlations)"
            else:
                verdict = "the d-set AIP degrades more (not what the paper predicts)"
            L.append(f"- off-policy data `{k}` ({d['off_policy_data'][k]['policy']}, options "
                     f"{d['off_policy_data'][k]['gs_options']}): the full-observation AIP's CE changes by "
                     f"{ce['full']['increase'][k]:+.3f}, the d-set AIP's by {ce['dset']['increase'][k]:+.3f} "
                     f"-> {verdict}.")
    L.append("")
    return L


def dset_section(out) -> list[str]:
    L = []
    for f in sorted(Path(out, "dset").glob("*/dset.json")):
        d = _load(f)
        if not d:
            continue
        L += _dset_table(f"### d-set ablation (paper §4.2): {d['env_id']} / {d['agent']} ({d['arch']} AIP, "
                         f"trained on {d['train_steps']} steps from the {d['train_policy']} policy)", d)
        if d.get("reverse"):
            r = d["reverse"]
            L += _dset_table(f"Reverse direction: trained on {r['train_steps']} steps from the "
                             f"{r['train_policy']}, tested on the other policies' data", r)
    return L


def write_report(out, leaderboard, cfg_note: dict | None = None) -> Path:
    """Re-make every figure and ``<leaderboard>/reproduction.md`` from the run folders."""
    out, lb = Path(out), Path(leaderboard)
    lb.mkdir(parents=True, exist_ok=True)
    cfg_note = cfg_note or {}
    runs = load_runs(out, "training")
    summaries = summarize_training(runs)

    def budget_note(env_id: str) -> str:
        mine = [r for r in runs if r["job"]["params"]["env_id"] == env_id]
        budgets = sorted({r["job"]["params"]["total_timesteps"] for r in mine})
        return (f"PPO budget {', '.join(f'{b:,}' for b in budgets) or '-'} steps per run (paper: 2,000,000); "
                f"policy net {', '.join(sorted({r['job']['params']['net_arch'] for r in mine})) or '-'}; "
                "wall-clocks are those of the machine that ran the study (2 cores here): runs that shared it "
                "(`--jobs 2`, other work) are slower and noisier than runs that had it to themselves (`--jobs 1`).")
    L = ["# Reproduction of the paper's experiments", "",
         "Generated by `ials-zoo reproduce` (re-make with `ials-zoo reproduce --report-only`); every number "
         "below is read from the run folders under " f"`{out}`.", ""]
    L += ["How to run: `ials-zoo reproduce [--experiments training,memory,dset] [--domains ...] [--budget N | "
          "DOMAIN=N,...] [--seeds 3] [--jobs 2]`. Every run is a subprocess writing into its own folder; a run "
          "whose `result.json` exists is skipped, so the study can be continued in later sessions with the same "
          "command (a folder holding a run of other settings is refused, never mixed in).", ""]
    if cfg_note:
        L += ["Study settings: " + ", ".join(f"{k}={v}" for k, v in cfg_note.items()), ""]
    L += ["## What the paper reported (SPEC §4)", "",
          "| | traffic | warehouse |", "|---|---|---|",
          "| 2M steps of PPO on the GS | 6.16 h | 13.1 h |",
          "| 2M steps of PPO on the IALS | 2.13 h | 3.9 h |",
          "| data collection + AIP training | 104 s + 36 s | 112 s + 207 s |",
          "| AIP test cross-entropy, trained / untrained | 0.22 / 0.78 | 0.362 / 1.46 |", "",
          "Claims: IALS-trained policies match GS-trained ones on the GS in about 1/3 of the wall-clock; "
          "untrained-IALS clearly worse in traffic; F-IALS 0.1 close in traffic, not in the warehouse.", "",
          "## What we measured", ""]
    if not summaries:
        L += ["No training runs yet.", ""]
    for key, s in summaries.items():
        env_id, agent = key
        png = f"reproduction_{env_id}__{agent}.png"
        refs = reference_scores(lb, env_id, agent)
        if any(v["curve"] for v in s["simulators"].values()):
            plot_training(s, refs, lb / png, f"{env_id} / {agent}: GS score vs wall-clock")
        aip = _load(out / "training" / f"{env_id}__{agent}" / "aip" / "report.json")
        L += training_section(key, s, aip, refs, png, budget_note(env_id))
    L += memory_section(out, lb) + dset_section(out)
    path = lb / "reproduction.md"
    atomic_write_text(path, "\n".join(L) + "\n")
    summary_json = {f"{k[0]}/{k[1]}": {lab: {kk: vv for kk, vv in v.items() if kk != "curve"}
                                       for lab, v in s["simulators"].items()} for k, s in summaries.items()}
    atomic_write_text(out / "summary.json", json.dumps(summary_json, indent=2, default=str) + "\n")
    return path


def submit_results(out, leaderboard, experiments=("training",)) -> dict:
    """Submit the study's finished configurations to the leaderboard with the project's own
    :func:`ials_zoo.leaderboard.submit`: one entry per (domain, agent, simulator, budget),
    its seeds merged (:func:`ials_zoo.leaderboard.merge_results`: a score per seed and the
    95% CI over seeds). A configuration with a seed still running is left for later, so the
    board never holds a partial merge; results already on the board are skipped.

    Returns ``{"submitted": [...], "already": [...], "rejected": [...], "incomplete": [...]}``."""
    from ials_zoo.leaderboard import ResultError, content_hash, load_entries, merge_results, submit
    from ials_zoo.utils import atomic_write_text

    have = {content_hash(d) for _, d in load_entries(leaderboard)}
    done = {"submitted": [], "already": [], "rejected": [], "incomplete": []}
    for exp in experiments:
        runs = load_runs(out, exp)
        configs = group(runs, lambda r: (r["job"]["params"]["env_id"], r["job"]["params"]["agent"],
                                         r["job"]["label"], r["job"]["params"]["total_timesteps"]))
        for (env_id, agent, label, steps), rs in sorted(configs.items()):
            name = f"{exp}/{env_id}/{agent}/{label_of(label)}/{steps}"
            if any(r["result"] is None for r in rs):
                done["incomplete"].append(name)
                continue
            rs = sorted(rs, key=lambda r: r["job"]["params"]["seed"])
            try:
                result = (rs[0]["result"] if len(rs) == 1 else
                          merge_results([r["result"] for r in rs],
                                        notes=f"ials-zoo reproduce ({exp}, {label}, {steps:,} steps), "
                                              f"{len(rs)} training seeds merged"))
            except ResultError as exc:
                done["rejected"].append(f"{name}: {exc}")
                continue
            if content_hash(result) in have:
                done["already"].append(name)
                continue
            # submit() reads a file: the merged result is written next to the runs first
            path = Path(out) / exp / f"{env_id}__{agent}" / f"{label_of(label)}__{steps}__merged.json"
            if len(rs) == 1:
                path = rs[0]["dir"] / "result.json"
            else:
                atomic_write_text(path, json.dumps(result, indent=2) + "\n")
            try:
                dest = submit(path, leaderboard)
            except ResultError as exc:
                done["rejected"].append(f"{name}: {exc}")
                continue
            have.add(content_hash(result))
            done["submitted"].append(str(dest))
    return done
