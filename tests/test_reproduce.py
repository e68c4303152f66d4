"""ials-zoo reproduce: planning, a tiny real study with resumption, item lifetimes, the d-set
ablation's off-policy cross-entropy, and the memory experiment's PPO on a domain variant."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ials_zoo.policy import PolicyNetwork, save_policy
from ials_zoo.reproduce import Config, build_plan, describe_plan, reproduce
from ials_zoo.reproduce import experiments as X
from ials_zoo.reproduce.claims import aggregate_curves, time_to_reach
from ials_zoo.reproduce.runner import run_jobs

# ---------------------------------------------------------------------------------- planning


def test_dry_run_plans_the_right_runs(tmp_path):
    cfg = Config(out=str(tmp_path / "out"), seeds=2, budget=12345, agents=("tls_12", "tls_18"),
                 eval_points=5)
    jobs = build_plan(cfg)
    ids = [j.id for j in jobs]
    assert len(ids) == len(set(ids))
    ppo = [j for j in jobs if j.kind == "ppo" and j.experiment == "training"]
    # 3 agents (robot_20, tls_12, tls_18) x 4 simulators x 2 seeds
    assert len(ppo) == 3 * 4 * 2
    assert {(j.params["agent"], j.label) for j in ppo} == {
        (a, s) for a in ("robot_20", "tls_12", "tls_18") for s in ("gs", "ials", "untrained-ials", "fixed:0.1")}
    for j in ppo:
        assert j.params["total_timesteps"] == 12345
        assert j.params["eval_every"] == 2469  # ceil(12345 / 5)
        assert j.marker == "run/result.json" and j.params["out_dir"] == str(Path(j.dir) / "run")
        if j.label == "ials":
            # the AIP trained (and timed) by this study, not a shipped file
            (dep,) = j.deps
            aip = next(a for a in jobs if a.id == dep)
            assert aip.kind == "aip" and j.params["simulator"] == str(Path(aip.dir) / "aip.pt")
        else:
            assert j.deps == [] and j.params["simulator"] == j.label
    mem = [j for j in jobs if j.experiment == "memory" and j.kind == "ppo"]
    assert len(mem) == 2 * 2 * 2  # {M, NM}-IALS x frame stack {8, 1} x 2 seeds
    assert {(j.label, j.params["frame_stack"]) for j in mem} == {
        ("M-IALS fs8", 8), ("M-IALS fs1", 1), ("NM-IALS fs8", 8), ("NM-IALS fs1", 1)}
    assert all(json.loads(j.params["env_options"]) == {"item_lifetime": 8} for j in mem)
    from ials_zoo.baselines.ppo_single import Args

    Args(**mem[0].params)  # ppo_single takes every planned parameter
    # SUMO collects Algorithm 1's data in collect_workers processes; the numpy warehouse in one
    workers = {j.params["agent"]: j.params.get("workers", 1) for j in jobs if j.kind == "aip" and j.experiment == "training"}
    assert workers == {"robot_20": 1, "tls_12": cfg.collect_workers, "tls_18": cfg.collect_workers} and cfg.collect_workers == 2
    arch = {j.id: j.params.get("arch") for j in jobs if j.kind == "aip" and j.experiment == "memory"}
    assert sorted(arch.values()) == ["gru", "mlp"]
    assert len([j for j in jobs if j.kind == "lifetimes"]) == 1
    assert sorted(j.params["env_id"] for j in jobs if j.kind == "dset") == ["traffic_grid_v0", "warehouse_v0"]
    # nothing ran: every job is todo and nothing was written
    assert "0 already done" in describe_plan(jobs)
    assert not (tmp_path / "out").exists()


def test_dry_run_command(tmp_path, capsys):
    from ials_zoo.cli import main

    rc = main(["reproduce", "--dry-run", "--experiments", "training", "--domains", "warehouse_v0",
               "--seeds", "1", "--out", str(tmp_path / "o")])
    assert rc == 0
    out = capsys.readouterr().out
    assert "5 jobs, 0 already done, 5 to run" in out
    assert "training/warehouse_v0/robot_20/ials/s0" in out and "traffic" not in out


@pytest.mark.parametrize("kw, word", [
    ({"experiments": ("training", "speed")}, "speed"),
    ({"domains": ("chess_v0",)}, "chess_v0"),
    ({"simulators": ("ials",)}, "gs"),
    ({"simulators": ("gs", "fixed:0.3")}, "fixed:0.3"),
    ({"budget": 0}, "budget"),
    ({"seeds": -1}, "seeds"),
    ({"agents": ("car_3",)}, "car_3"),
])
def test_bad_config_is_named(kw, word):
    with pytest.raises(ValueError, match=word):
        Config(**kw).check()


# ------------------------------------------------------------------------- a tiny real study


def test_tiny_training_study_runs_reports_and_resumes(tmp_path):
    lb = tmp_path / "lb"
    cfg = Config(experiments=("training",), domains=("warehouse_v0",),
                 simulators=("gs", "ials", "untrained-ials"), seeds=1, budget=512, n_envs=2,
                 net_arch="8", eval_points=1, eval_episodes=1, final_eval_episodes=2,
                 aip_steps=1000, aip_epochs=1, out=str(tmp_path / "out"), leaderboard=str(lb))
    res = reproduce(cfg, progress=False)
    assert res["jobs"]["failed"] == [] and res["jobs"]["blocked"] == []
    assert len(res["jobs"]["done"]) == 4  # AIP + 3 PPO runs
    base = tmp_path / "out" / "training" / "warehouse_v0__robot_20"
    for sim in ("gs", "ials", "untrained-ials"):
        r = json.loads((base / f"{sim}__s0" / "run" / "result.json").read_text())
        assert r["training"]["env_steps"] >= 512
        assert (base / f"{sim}__s0" / "run" / "curve.json").is_file()
        assert (base / f"{sim}__s0" / "log.txt").is_file()
    # the IALS run is charged the AIP time measured by this study
    aip = json.loads((base / "aip" / "report.json").read_text())
    ials = json.loads((base / "ials__s0" / "run" / "result.json").read_text())
    assert ials["training"]["aip_seconds"] == pytest.approx(
        aip["dataset"]["collect_seconds"] + aip["train_seconds"])
    assert aip["dataset"]["steps"] == 1000
    assert (lb / "reproduction_warehouse_v0__robot_20.png").stat().st_size > 1000
    md = (lb / "reproduction.md").read_text()
    for sim in ("gs", "ials", "untrained-ials"):
        assert f"| {sim} | 1/1 |" in md
    assert "6.16 h" in md and "test CE trained" in md
    assert len(res["leaderboard"]["submitted"]) == 3
    assert len(list((lb / "results").glob("*.json"))) == 3

    # Resuming: nothing runs again, nothing is resubmitted.
    stamp = {p: p.stat().st_mtime_ns for p in base.glob("*/result.json")}
    again = reproduce(cfg, progress=False)
    assert again["jobs"]["done"] == [] and len(again["jobs"]["skipped"]) == 4
    assert {p: p.stat().st_mtime_ns for p in base.glob("*/result.json")} == stamp
    assert again["leaderboard"]["submitted"] == [] and len(again["leaderboard"]["already"]) == 3
    # A run without its result.json (e.g. interrupted) is the only one that runs again.
    (base / "untrained-ials__s0" / "run" / "result.json").unlink()
    status = run_jobs(build_plan(cfg), n_jobs=2, progress=False)
    assert status["done"] == ["training/warehouse_v0/robot_20/untrained-ials/s0"]
    assert (base / "untrained-ials__s0" / "run" / "result.json").is_file()


def test_failed_job_blocks_its_dependants(tmp_path):
    # An AIP job that cannot succeed (bad steps) must not start the IALS runs depending on it.
    cfg = Config(experiments=("training",), domains=("warehouse_v0",), simulators=("gs", "ials"),
                 seeds=1, out=str(tmp_path / "o"))
    jobs = [j for j in build_plan(cfg) if j.kind == "aip" or j.label == "ials"]
    jobs[0].params["steps"] = -5
    status = run_jobs(jobs, n_jobs=1, progress=False)
    assert status["failed"] == [jobs[0].id] and status["blocked"] == [jobs[1].id]
    assert "steps must be >= 1" in (Path(jobs[0].dir) / "log.txt").read_text()
    assert not Path(jobs[1].dir).exists()


def test_aggregate_curves_and_time_to_reach():
    a = [{"wall_clock_seconds": 0.0, "mean": 0.0}, {"wall_clock_seconds": 10.0, "mean": 10.0}]
    b = [{"wall_clock_seconds": 0.0, "mean": 2.0}, {"wall_clock_seconds": 20.0, "mean": 22.0}]
    agg = aggregate_curves([a, b], n=11)
    assert agg["seeds"] == 2 and agg["seconds"][0] == 0.0 and agg["seconds"][-1] == 10.0  # common span
    assert agg["mean"][0] == pytest.approx(1.0) and agg["mean"][-1] == pytest.approx(11.0)
    assert agg["ci_low"][-1] < 11.0 < agg["ci_high"][-1]
    assert time_to_reach(agg, 6.0) == pytest.approx(5.0)
    assert time_to_reach(agg, 100.0) is None
    assert aggregate_curves([]) is None


# ------------------------------------------------------------------------------ item lifetimes


def test_item_lifetimes_constructed():
    ages = np.array([[0, 1, 0], [1, 2, 0], [2, 3, 1], [0, 1, 2], [0, 2, 3]])
    # cell 0: an item of 2 collected; cell 1: an item of 3 replaced at once by a new one
    # (still present at the end: censored); cell 2: still present at the end (censored)
    assert X.item_lifetimes(ages) == [2, 3]
    with pytest.raises(ValueError, match="shape"):
        X.item_lifetimes(np.zeros(5))


def _patrol():
    state = {"t": 0}

    def act(obs):  # up/down in the region's interior: never on a shelf cell, never collects
        state["t"] += 1
        return state["t"] % 2

    return act


def test_item_lifetime_8_in_gs_when_nobody_collects():
    # One robot alone (no neighbours) that never steps on a shelf: every item lives 8 steps.
    ages = X.record_item_ages("warehouse_v0", "robot_0", "gs", episodes=2, policy=_patrol(),
                              item_lifetime=8, robots=(1, 1))
    lives = [x for a in ages for x in X.item_lifetimes(a)]
    assert ages[0].shape == (101, 12) and len(lives) > 20
    assert set(lives) == {8}
    # With scripted neighbours collecting shared items, some items go earlier.
    ages = X.record_item_ages("warehouse_v0", "robot_20", "gs", episodes=2, policy=_patrol(), item_lifetime=8)
    lives = [x for a in ages for x in X.item_lifetimes(a)]
    assert max(lives) == 8 and min(lives) < 8


def test_lifetimes_job_writes_histogram(tmp_path):
    params = {"env_id": "warehouse_v0", "agent": "robot_20", "options": {"item_lifetime": 8},
              "episodes": 1, "aips": {"untrained": "untrained"}}
    d = X.run_lifetimes(params, tmp_path)
    assert set(d["lifetimes"]) == {"GS", "untrained"}
    assert all(1 <= x <= 8 for v in d["lifetimes"].values() for x in v)
    assert len(d["lifetimes"]["untrained"]) > 5  # items appear and go in the IALS too
    assert (tmp_path / "lifetimes.png").stat().st_size > 1000
    assert json.loads((tmp_path / "lifetimes.json").read_text())["summary"]["GS"]["items"] == len(d["lifetimes"]["GS"])


# ------------------------------------------------------------------------------- d-set ablation


def _confounded(region, rng, E, T, follow: bool):
    """u is 0 or 3 in every source; full bit 0 equals [u == 0] when ``follow`` (a spurious
    cue), else it is independent of u; the d-set carries no information about u."""
    from ials_zoo.influence.dataset import InfluenceDataset

    zero = rng.random((E, T)) < 0.5
    u = np.where(zero, 0, 3)[:, :, None].repeat(region.n_sources, axis=2)
    full = (rng.random((E, T, region.dset_size("full"))) < 0.5).astype(np.uint8)
    full[:, :, 0] = zero if follow else rng.random((E, T)) < 0.5
    dset = (rng.random((E, T, region.dset_size("dset"))) < 0.5).astype(np.uint8)
    return InfluenceDataset(region, {"dset": dset, "full": full}, u, {"collect_seconds": 0.0})


def test_off_policy_cross_entropy_exposes_a_spurious_cue():
    from ials_zoo.core.domains import get_domain
    from ials_zoo.influence.train import train_predictor

    region = get_domain("warehouse_v0").region_spec("robot_20")
    rng = np.random.default_rng(0)
    on = _confounded(region, rng, 20, 50, follow=True)
    off = _confounded(region, rng, 5, 50, follow=False)
    preds = {k: train_predictor(on, arch="mlp", dset_kind=k, epochs=15, lr=1e-2, progress=False)[0]
             for k in ("dset", "full")}
    _, test = on.split(0.1)
    ce = X.off_policy_cross_entropy(preds, on, test, {"other": off})
    from ials_zoo.influence.metrics import evaluate_cross_entropy

    assert ce["full"]["off_policy"]["other"] == pytest.approx(evaluate_cross_entropy(preds["full"], off))
    assert ce["full"]["on_policy"] < 0.3  # it learned the cue...
    assert ce["full"]["increase"]["other"] > 1.0  # ...which misleads it off-policy
    assert abs(ce["dset"]["increase"]["other"]) < 0.1  # the d-set AIP cannot be fooled
    with pytest.raises(ValueError, match="empty"):
        X.off_policy_cross_entropy({}, on, test, {})


def test_dset_ablation_job_on_warehouse(tmp_path):
    params = {"env_id": "warehouse_v0", "agent": "robot_20", "steps": 1000, "offpolicy_steps": 200,
              "epochs": 1, "seed": 0}
    d = X.dset_ablation(params, tmp_path / "dset" / "wh")
    assert set(d["cross_entropy"]) == {"dset", "full", "marginal", "uniform", "untrained"}
    assert d["off_policy_data"]["scripted"]["gs_options"] == {"scripted_learners": True}
    assert d["off_policy_data"]["biased"]["policy"].startswith("biased_random")
    for c in d["cross_entropy"].values():
        assert np.isfinite(c["on_policy"]) and all(np.isfinite(v) for v in c["off_policy"].values())
    assert json.loads((tmp_path / "dset" / "wh" / "dset.json").read_text())["train_steps"] == 1000
    rev = d["reverse"]
    assert rev["train_steps"] == 200 and set(rev["off_policy_data"]) == {"random", "biased"}
    assert set(rev["cross_entropy"]["full"]["off_policy"]) == {"random", "biased"}
    from ials_zoo.reproduce.report import dset_section

    text = "\n".join(dset_section(tmp_path))
    assert "Reverse direction" in text and "| full |" in text


def test_budget_option():
    from ials_zoo.commands.reproduce import parse_budget

    defaults = {"traffic_grid_v0": 300_000}
    assert parse_budget(None, 500_000, defaults) == (500_000, defaults)
    assert parse_budget("20000", 500_000, defaults) == (20_000, {})
    assert parse_budget("warehouse_v0=1000000", 500_000, defaults) == (
        500_000, {"traffic_grid_v0": 300_000, "warehouse_v0": 1_000_000})
    assert parse_budget("1000,traffic_grid_v0=50", 500_000, defaults) == (1000, {"traffic_grid_v0": 50})
    with pytest.raises(ValueError, match="lots"):
        parse_budget("lots", 500_000, defaults)
    cfg = Config(budget=1000, domain_budgets={"traffic_grid_v0": 50}, eval_points=4)
    assert (cfg.budget_for("warehouse_v0"), cfg.budget_for("traffic_grid_v0")) == (1000, 50)
    assert cfg.eval_every("traffic_grid_v0") == 13
    ppo = {j.params["env_id"]: j.params["total_timesteps"] for j in build_plan(cfg) if j.kind == "ppo"}
    assert ppo == {"warehouse_v0": 1000, "traffic_grid_v0": 50}
    with pytest.raises(ValueError, match="chess_v0"):
        Config(domain_budgets={"chess_v0": 5}).check()


def test_memory_budget_is_separate_from_the_training_budget():
    import argparse

    from ials_zoo.commands.reproduce import config_from_args, configure
    from ials_zoo.reproduce.plan import DEFAULT_MEMORY_BUDGET, default_budgets

    parser = argparse.ArgumentParser()
    configure(parser)

    def memory_steps(argv):
        cfg = config_from_args(parser.parse_args(argv))
        steps = {j.params["total_timesteps"] for j in build_plan(cfg) if j.experiment == "memory" and j.kind == "ppo"}
        (only,) = steps
        return only, cfg

    # defaults: the published study (2M warehouse training runs, 500k memory runs)
    steps, cfg = memory_steps([])
    assert steps == DEFAULT_MEMORY_BUDGET and cfg.budget_for("warehouse_v0") == default_budgets()["warehouse_v0"]
    assert memory_steps(["--memory-budget", "700"])[0] == 700
    # a quick study with --budget shrinks the memory runs too, unless told otherwise
    assert memory_steps(["--budget", "2000"])[0] == 2000
    assert memory_steps(["--budget", "2000", "--memory-budget", "900"])[0] == 900
    cfg = memory_steps(["--budget", "2000", "--memory-budget", "900"])[1]
    mem = next(j for j in build_plan(cfg) if j.experiment == "memory" and j.kind == "ppo")
    assert mem.params["eval_every"] == -(-900 // cfg.eval_points)
    with pytest.raises(ValueError, match="memory_budget"):
        Config(memory_budget=0).check()


def test_resuming_with_other_settings_is_refused(tmp_path):
    cfg = Config(experiments=("training",), domains=("warehouse_v0",), simulators=("gs",), seeds=1,
                 budget=1000, out=str(tmp_path / "o"))
    (job,) = [j for j in build_plan(cfg) if j.kind == "ppo"]
    job.write()
    assert job.conflict() is None
    cfg.budget = 2000
    (other,) = [j for j in build_plan(cfg) if j.kind == "ppo"]
    assert "total_timesteps" in other.conflict()
    assert "CONFLICT" in describe_plan([other])
    with pytest.raises(ValueError, match="other settings"):
        run_jobs([other], progress=False)


def test_interrupt_stops_running_jobs(tmp_path, monkeypatch):
    # A KeyboardInterrupt while a job runs stops that job (no result.json), and a later run
    # starts it again.
    import ials_zoo.reproduce.runner as runner

    cfg = Config(experiments=("training",), domains=("warehouse_v0",), simulators=("gs",), seeds=1,
                 budget=10_000_000, out=str(tmp_path / "o"))
    (job,) = [j for j in build_plan(cfg) if j.kind == "ppo"]
    calls = {"n": 0}
    real_sleep = runner.time.sleep

    def sleep(s):
        calls["n"] += 1
        if calls["n"] > 3:
            raise KeyboardInterrupt
        real_sleep(s)

    monkeypatch.setattr(runner.time, "sleep", sleep)
    with pytest.raises(KeyboardInterrupt):
        run_jobs([job], progress=False)
    assert not job.done and job.conflict() is None


def _run(label, seed, finals, curve, steps=1000, seconds=10.0, aip=0.0):
    return {"job": {"label": label, "params": {"env_id": "warehouse_v0", "agent": "robot_20", "seed": seed}},
            "curve": {"points": [{"wall_clock_seconds": t, "mean": m} for t, m in curve]},
            "result": {"score": {"mean": finals},
                       "training": {"wall_clock_seconds": seconds, "aip_seconds": aip, "env_steps": steps}}}


def test_summary_ratios_and_claims():
    from ials_zoo.reproduce.claims import summarize_training
    from ials_zoo.reproduce.report import training_section

    runs = [_run("gs", 0, 10.0, [(0, 0), (100, 10)], seconds=100),
            _run("gs", 1, 10.2, [(0, 0), (100, 10)], seconds=100),
            _run("ials", 0, 9.9, [(20, 0), (40, 10)], seconds=20, aip=20),
            _run("ials", 1, 10.1, [(20, 0), (40, 10)], seconds=20, aip=20),
            _run("untrained-ials", 0, 2.0, [(0, 0), (20, 2)], seconds=20),
            _run("untrained-ials", 1, 2.2, [(0, 0), (20, 2)], seconds=20)]
    (key, s), = summarize_training(runs).items()
    sims = s["simulators"]
    assert list(sims) == ["gs", "ials", "untrained-ials"]
    assert s["target_95pct"] == pytest.approx(9.5)
    assert sims["gs"]["seconds_to_95pct_gs"] == pytest.approx(95.0, abs=2.1)  # on a 50-point grid
    assert sims["ials"]["seconds_to_95pct_gs"] == pytest.approx(39.0, abs=0.5)
    assert sims["ials"]["time_ratio_to_gs"] == pytest.approx(
        sims["ials"]["seconds_to_95pct_gs"] / sims["gs"]["seconds_to_95pct_gs"])
    assert sims["ials"]["score_ratio_to_gs"] == pytest.approx(1.0 / 1.01)
    assert sims["ials"]["total_seconds"] == 40 and sims["ials"]["ppo_steps_per_second"] == 50
    assert sims["untrained-ials"]["seconds_to_95pct_gs"] is None
    text = "\n".join(training_section(key, s, None, {}, "x.png", "note"))
    assert "ratio 0.99 -> holds" in text and "ratio 0.41 -> does not hold" in text
    assert "-> yes (paper: yes in traffic)" in text


def test_second_invocation_on_the_same_study_is_refused(tmp_path):
    from ials_zoo.reproduce.runner import study_lock

    cfg = Config(experiments=("training",), domains=("warehouse_v0",), simulators=("gs",), seeds=1,
                 out=str(tmp_path / "o"))
    with study_lock(tmp_path / "o"):
        with pytest.raises(RuntimeError, match="another ials-zoo reproduce"):
            run_jobs(build_plan(cfg), progress=False, lock_dir=cfg.out)


def test_submit_merges_the_seeds_of_a_finished_configuration_only(tmp_path):
    from ials_zoo import leaderboard as lb
    from ials_zoo.evaluation import evaluate
    from ials_zoo.reproduce.report import submit_results

    base = tmp_path / "out" / "training" / "warehouse_v0__robot_20"

    def run(label, seed, action=None):
        d = base / f"{label}__s{seed}"
        d.mkdir(parents=True)
        params = {"env_id": "warehouse_v0", "agent": "robot_20", "seed": seed, "total_timesteps": 1000}
        (d / "job.json").write_text(json.dumps({"kind": "ppo", "label": label, "params": params}))
        if action is not None:  # a finished run: a real GS score of a fixed-action policy file
            (d / "run").mkdir()
            bias = np.full((1, 4), -50.0, np.float32)
            bias[0, action] = 50.0
            net = PolicyNetwork(["robot_20"], 37, 4, [(np.zeros((1, 37, 4), np.float32), bias)],
                                metadata={"env_id": "warehouse_v0"})
            policy = save_policy(net, d / "run" / "policy.safetensors")
            ev = evaluate("warehouse_v0", "robot_20", str(policy), episodes=2)
            result = lb.make_result([ev], algorithm="ppo_single", training_seeds=[seed], training={
                "simulator": label, "aip": None, "seeds": [seed], "env_steps": 1000,
                "wall_clock_seconds": 10.0 + seed, "aip_seconds": 0.0, "hyperparameters": {}})
            (d / "run" / "result.json").write_text(json.dumps(result))

    run("gs", 0, action=0)
    run("gs", 1, action=3)
    run("ials", 0, action=1)
    run("ials", 1)  # still running
    board = tmp_path / "lb"
    first = submit_results(tmp_path / "out", board)
    assert first["incomplete"] == ["training/warehouse_v0/robot_20/ials/1000"] and first["rejected"] == []
    (entry,) = [json.loads(p.read_text()) for p in (board / "results").glob("*.json")]
    assert [s["seed"] for s in entry["scores"]] == [0, 1] and entry["training"]["seeds"] == [0, 1]
    assert entry["training"]["wall_clock_seconds"] == pytest.approx(10.5)
    again = submit_results(tmp_path / "out", board)
    assert again["submitted"] == [] and again["already"] == ["training/warehouse_v0/robot_20/gs/1000"]
