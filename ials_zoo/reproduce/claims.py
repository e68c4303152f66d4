"""The study as data: runs read from their folders, summaries, and the paper's claims
computed from them (``ials-zoo reproduce``). Formatting lives in
:mod:`ials_zoo.reproduce.report`.

Everything is re-made from the run folders (``job.json``, ``curve.json``, ``result.json``,
``report.json``, ``lifetimes.json``, ``dset.json``), so a partly finished study is summarised as
far as it goes: missing runs are missing, never guessed.

Curves: each seed's GS learning curve (mean return vs wall-clock seconds, AIP collection and
training included) is interpolated linearly onto a common grid over the span every seed
covers; the band is the 95% Student-t interval over seeds (none with one seed).

A claim is a dict ``{"claim": text, "measured": ..., "holds": True | False | None, ...}``
(``holds`` None: not measured, or undecided with the seeds at hand).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ials_zoo.leaderboard import load_entries
from ials_zoo.reproduce.plan import DIALS_VARIANTS, KNOWN_SIMULATORS
from ials_zoo.stats import t_interval as mean_ci
from ials_zoo.utils import read_json_object

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


def _load(path: Path):
    try:
        return read_json_object(path, 4 << 20, what="run file")
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
        run = d / "run"
        runs.append({"job": job, "dir": run, "curve": _load(run / "curve.json"), "result": _load(run / "result.json")})
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

    return (KNOWN_SIMULATORS.index(label) if label in KNOWN_SIMULATORS else len(KNOWN_SIMULATORS), label)


def paper_steps_per_second(env_id: str) -> dict:
    """PPO throughput implied by SPEC §4 (2M steps / reported hours)."""
    p = PAPER[env_id]
    return {"gs": 2e6 / (p["gs_hours"] * 3600), "ials": 2e6 / (p["ials_hours"] * 3600)}


def reference_scores(leaderboard, env_id: str, agent: str) -> dict:
    """Scores of the reference policies (entries without training) on the board."""

    refs = {}
    try:
        entries, _ = load_entries(leaderboard)
    except (OSError, ValueError):
        return refs
    for _, d in entries:
        if d.get("env_id") == env_id and d.get("agent") == agent and d.get("training") is None:
            refs[d["algorithm"]] = d["score"]["mean"]
    return refs


def _ratio(a, b):
    return a / b if a is not None and b else None


def training_claims(env_id: str, summary: dict, aip_report: dict | None) -> list[dict]:
    """The paper's claims about one (domain, agent) of the training experiment."""
    sims = summary["simulators"]
    paper = PAPER.get(env_id, {})
    ials, gs = sims.get("ials", {}), sims.get("gs", {})
    out = []
    r = ials.get("score_ratio_to_gs")
    out.append({"id": "score", "claim": f"IALS policy scores >= {TARGET_SCORE_RATIO:.0%} of the GS policy on the GS",
                "measured": r, "holds": None if r is None else r >= TARGET_SCORE_RATIO})
    tr = ials.get("time_ratio_to_gs")
    out.append({"id": "time_to_95", "claim": "IALS reaches 95% of the end of the GS's curve in <= 1/3 of the GS's wall-clock",
                "measured": tr, "ials_seconds": ials.get("seconds_to_95pct_gs"), "gs_seconds": gs.get("seconds_to_95pct_gs"),
                "never_reached": bool(gs.get("seconds_to_95pct_gs") and ials.get("final_mean") is not None
                                      and ials.get("seconds_to_95pct_gs") is None),
                "holds": None if tr is None else tr <= TARGET_TIME_RATIO})
    total = _ratio(ials.get("total_seconds"), gs.get("total_seconds"))
    out.append({"id": "total_time", "claim": "total training wall-clock for the same step budget, AIP included, IALS vs GS "
                "(the paper's own measure)", "measured": total, "ials_seconds": ials.get("total_seconds"),
                "gs_seconds": gs.get("total_seconds"),
                "holds": None if total is None else total <= TARGET_TIME_RATIO,
                "holds_one_fifth": None if total is None else total <= 0.2})
    un = sims.get("untrained-ials", {})
    if un.get("final_mean") is not None and ials.get("final_mean") is not None:
        decided = min(un["finished"], ials["finished"]) >= 2
        out.append({"id": "untrained_worse", "claim": "untrained-IALS clearly worse than IALS (95% CIs over seeds disjoint)",
                    "measured": (un["final_mean"], ials["final_mean"]),
                    "holds": (un["final_ci_high"] < ials["final_ci_low"]) if decided else None,
                    "undecided": not decided, "paper": "yes in traffic"})
    fx = sims.get("fixed:0.1", {})
    if fx.get("score_ratio_to_gs") is not None:
        out.append({"id": "fixed_close", "claim": f"F-IALS 0.1 close to the GS (>= {TARGET_SCORE_RATIO:.0%})",
                    "measured": fx["score_ratio_to_gs"], "holds": fx["score_ratio_to_gs"] >= TARGET_SCORE_RATIO,
                    "paper": "yes in traffic, no in the warehouse"})
    if aip_report:
        ce = aip_report["cross_entropy"]
        t, u = ce["trained"]["test"], ce["untrained"]["test"]
        out.append({"id": "ce", "claim": "AIP test CE trained << untrained", "measured": (t, u),
                    "ratio": t / max(u, 1e-12), "holds": t < u,
                    "paper": (paper.get("ce_trained"), paper.get("ce_untrained"))})
    if gs.get("ppo_steps_per_second") and ials.get("ppo_steps_per_second") and paper:
        ps = paper_steps_per_second(env_id)
        out.append({"id": "throughput", "claim": "PPO throughput IALS / GS",
                    "measured": ials["ppo_steps_per_second"] / gs["ppo_steps_per_second"],
                    "ials": ials["ppo_steps_per_second"], "gs": gs["ppo_steps_per_second"],
                    "paper": paper["gs_hours"] / paper["ials_hours"], "paper_ials": ps["ials"], "paper_gs": ps["gs"],
                    "holds": None})
    return out


def memory_stats(runs: list[dict]) -> dict:
    """Per (env_id, agent): per (AIP name, frame stack label) the finished seeds' final scores
    and their mean/CI (None with fewer than 2 seeds)."""
    out = {}
    for key, rs in group(runs, lambda r: (r["job"]["params"]["env_id"], r["job"]["params"]["agent"])).items():
        rows = {}
        for label, srs in sorted(group(rs, lambda r: r["job"]["label"]).items()):
            finals = [r["result"]["score"]["mean"] for r in srs if r["result"]]
            name, fs = label.split(" ")
            rows[(name, fs)] = {"planned": len(srs), "finals": finals,
                                "stats": mean_ci(finals) if finals else None,
                                "budgets": sorted({r["job"]["params"]["total_timesteps"] for r in srs})}
        out[key] = rows
    return dict(sorted(out.items()))


def memory_claims(rows: dict, memory_stack: str = "fs8") -> list[dict]:
    """The paper's memory claim per agent kind: M-IALS vs NM-IALS, CIs over seeds."""
    out = []
    for fs, what in ((memory_stack, "agent with memory"), ("fs1", "agent without memory")):
        m, nm = rows.get(("M-IALS", fs)), rows.get(("NM-IALS", fs))
        if not (m and nm and len(m["finals"]) > 1 and len(nm["finals"]) > 1):
            out.append({"claim": what, "holds": None, "measured": None})
            continue
        a, b = m["stats"], nm["stats"]
        disjoint = a[1] > b[2] or b[1] > a[2]
        out.append({"claim": what, "measured": (a[0], b[0]), "disjoint": disjoint,
                    "better": ("M-IALS" if a[0] > b[0] else "NM-IALS") if disjoint else None, "holds": None})
    return out


def dset_verdicts(d: dict) -> list[dict]:
    """Per off-policy data set: how much more the full-observation AIP's CE grows than the
    d-set AIP's (``gap``), and what that says."""
    ce = d["cross_entropy"]
    out = []
    if "dset" in ce and "full" in ce:
        for k in d["off_policy_data"]:
            gap = ce["full"]["increase"][k] - ce["dset"]["increase"][k]
            if abs(gap) < CLEAR_CE_GAP:
                verdict = f"no clear difference (|gap| {abs(gap):.3f} < {CLEAR_CE_GAP} nats)"
            elif gap > 0:
                verdict = "the full-history AIP degrades more (consistent with spurious correlations)"
            else:
                verdict = "the d-set AIP degrades more (not what the paper predicts)"
            out.append({"data": k, "gap": gap, "full": ce["full"]["increase"][k], "dset": ce["dset"]["increase"][k],
                        "verdict": verdict})
    return out


# --------------------------------------------------------------------------------------------
# Every agent learning at once (the dials experiment)

# Issue targets, on the same cores: DIALS's joint GS score >= 95% of GS-IPPO's and its
# wall-clock for the same steps <= 1/2 of GS-IPPO's.
DIALS_SCORE_RATIO = 0.95
DIALS_TIME_RATIO = 1 / 2


def load_multiagent_runs(out) -> list[dict]:
    """Every multi-agent run folder of the dials experiment: ``{job, curve, result, dir}``."""
    runs = []
    for jf in sorted(Path(out, "dials").glob("*/*/job.json")):
        job = _load(jf)
        if not job or job.get("kind") != "multiagent":
            continue
        run = jf.parent / "run"
        runs.append({"job": job, "dir": run, "curve": _load(run / "curve.json"), "result": _load(run / "result.json")})
    return runs


def joint_references(out, env_id: str) -> dict:
    """``{"joint scripted": score, "joint random": score}`` of the study's reference runs."""
    refs = {}
    for jf in sorted(Path(out, "dials", env_id).glob("joint-*/result.json")):
        r = _load(jf)
        if r:
            refs[f"joint {r['policy']['name']}"] = r["score"]["mean"]
    return refs


def _total_seconds(result: dict) -> float:
    t = result["training"]
    return float(t["wall_clock_seconds"]) + float(t["aip_seconds"])


def summarize_dials(runs: list[dict]) -> dict:
    """Per domain: per variant (label), the joint GS scores over seeds, wall-clocks (training
    and AIP), the curve over seeds, and the ratios to GS-IPPO; plus the parallel efficiency of
    the 1-worker run against the same run (seed 0) on more workers."""
    out = {}
    for env_id, rs in sorted(group(runs, lambda r: r["job"]["params"]["env_id"]).items()):
        variants = {}
        for label, vrs in group(rs, lambda r: r["job"]["label"]).items():
            done = [r for r in vrs if r["result"]]
            finals = [r["result"]["score"]["mean"] for r in done]
            m, lo, hi = mean_ci(finals) if finals else (None, None, None)
            variants[label] = {
                "planned": len(vrs), "finished": len(done), "seeds": [r["job"]["params"]["seed"] for r in done],
                "final_mean": m, "final_ci_low": lo, "final_ci_high": hi, "final_per_seed": finals,
                "total_seconds": float(np.mean([_total_seconds(r["result"]) for r in done])) if done else None,
                "aip_seconds": float(np.mean([r["result"]["training"]["aip_seconds"] for r in done])) if done else None,
                "steps_per_agent": int(done[0]["result"]["training"]["env_steps"]) if done else None,
                "workers": sorted({r["job"]["params"].get("workers", 0) for r in vrs}),
                "curve": aggregate_curves([r["curve"]["points"] for r in vrs if r["curve"]]),
                "per_seed": {r["job"]["params"]["seed"]: r["result"] for r in done},
            }

        order = {v: i for i, v in enumerate(DIALS_VARIANTS)}
        variants = dict(sorted(variants.items(), key=lambda kv: (order.get(kv[0], len(order)), kv[0])))
        ippo = variants.get("ippo", {})
        for s in variants.values():
            s["score_ratio_to_ippo"] = _ratio(s["final_mean"], ippo.get("final_mean"))
            s["time_ratio_to_ippo"] = _ratio(s["total_seconds"], ippo.get("total_seconds"))
        out[env_id] = {"variants": variants, "parallel": parallel_efficiency(variants)}
    return out


def parallel_efficiency(variants: dict) -> dict | None:
    """Speed-up and efficiency of the periodic DIALS run of seed 0 on its workers against the
    same run on one worker (training wall-clock, AIP work included), and whether both gave the
    same joint score (they should: a run does not depend on its worker count)."""
    one = variants.get("dials (1 worker)", {}).get("per_seed", {}).get(0)
    many = variants.get("dials", {}).get("per_seed", {}).get(0)
    if not one or not many:
        return None
    workers = max(variants["dials"]["workers"])
    t1, tn = _total_seconds(one), _total_seconds(many)
    train1, trainn = one["training"]["wall_clock_seconds"], many["training"]["wall_clock_seconds"]
    return {"workers": workers, "seconds_1": t1, "seconds_n": tn, "speedup": t1 / tn, "efficiency": t1 / tn / workers,
            "train_seconds_1": train1, "train_seconds_n": trainn, "train_speedup": train1 / trainn,
            "same_score": one["score"]["mean"] == many["score"]["mean"]}


def dials_claims(summary: dict) -> list[dict]:
    """The issue's targets for one domain, computed from :func:`summarize_dials`."""
    v = summary["variants"]
    dials, untrained = v.get("dials", {}), v.get("untrained-dials", {})
    claims = []
    for label in ("dials", "dials-once"):
        s = v.get(label, {})
        r = s.get("score_ratio_to_ippo")
        claims.append({"id": "score", "label": label, "measured": r,
                       "holds": None if r is None else r >= DIALS_SCORE_RATIO})
        t = s.get("time_ratio_to_ippo")
        claims.append({"id": "time", "label": label, "measured": t,
                       "holds": None if t is None else t <= DIALS_TIME_RATIO})
    if untrained.get("final_mean") is not None and dials.get("final_mean") is not None:
        undecided = untrained["finished"] < 2 or dials["finished"] < 2
        worse = (not undecided) and untrained["final_ci_high"] < dials["final_ci_low"]
        claims.append({"id": "untrained_worse", "measured": (untrained["final_mean"], dials["final_mean"]),
                       "holds": None if undecided else worse})
    return claims
