"""The dials study of ``ials-zoo reproduce`` (plan, scheduling, summary) and the shipped AIP sets."""

from __future__ import annotations

import dataclasses
import json

import pytest

from ials_zoo.reproduce import Config, build_plan
from ials_zoo.reproduce.plan import DEFAULT_DIALS_VARIANTS, DIALS_VARIANTS


def test_dials_plan_has_every_variant_seed_references_and_a_one_worker_repeat(tmp_path):
    cfg = Config(experiments=("dials",), domains=("warehouse_v0",), seeds=2, out=str(tmp_path),
                 dials_budgets={"warehouse_v0": 2048})
    assert "dials-fidelity" in DIALS_VARIANTS and "dials-fidelity" not in cfg.dials_variants == DEFAULT_DIALS_VARIANTS
    jobs = build_plan(dataclasses.replace(cfg, dials_variants=DIALS_VARIANTS))
    multi = [j for j in jobs if j.kind == "multiagent"]
    assert len(multi) == len(DIALS_VARIANTS) * 2 + 1
    assert all(j.exclusive for j in multi) and not any(j.exclusive for j in jobs if j.kind != "multiagent")
    assert {j.params["policy"] for j in jobs if j.kind == "joint-reference"} == {"scripted", "random"}
    by_label = {}
    for j in multi:
        by_label.setdefault(j.label, []).append(j)
    assert by_label["ippo"][0].params["algorithm"] == "ippo" and "refresh" not in by_label["ippo"][0].params
    assert by_label["dials"][0].params["refresh"] == "1024"  # every half budget
    assert by_label["dials-once"][0].params["refresh"] == "once"
    un = by_label["untrained-dials"][0].params
    assert un["aip"] == "untrained" and un["refresh"] == "never"
    fid = by_label["dials-fidelity"][0].params
    assert fid["aip_training"] == "fidelity" and fid["refresh"] == "1024"
    (one,) = by_label["dials (1 worker)"]
    assert one.params["workers"] == 1 and one.params["seed"] == 0
    assert all(j.params["total_timesteps"] == 2048 for j in multi)
    # seed by seed: every variant of seed 0 starts before any run of seed 1
    order = sorted(multi, key=lambda j: j.priority())
    seeds = [j.params["seed"] for j in order]
    assert seeds == sorted(seeds)


def test_every_planned_run_passes_its_baselines_argument_check(tmp_path):
    from importlib import import_module

    cfg = Config(experiments=("dials",), domains=("traffic_grid_v0", "warehouse_v0"), seeds=1, out=str(tmp_path),
                 dials_variants=DIALS_VARIANTS)
    for job in build_plan(cfg):
        if job.kind != "multiagent":
            continue
        p = dict(job.params)
        module = import_module(f"ials_zoo.baselines.{p.pop('algorithm')}")
        args = module.Args(**p)
        module.check_args(args)  # raises on anything a run would refuse


@pytest.mark.parametrize("kw, word", [({"dials_variants": ("dials", "bogus")}, "dials_variants"),
                                      ({"dials_budgets": {"warehouse_v0": 0}}, "dials budget"),
                                      ({"dials_budgets": {"nowhere_v0": 10}}, "nowhere_v0"),
                                      ({"dials_workers": 0}, "dials_workers")])
def test_bad_dials_settings_are_named(kw, word):
    with pytest.raises(ValueError, match=word):
        Config(experiments=("dials",), **kw).check()


def test_exclusive_jobs_run_alone(tmp_path, monkeypatch):
    # Two multi-agent jobs and two light jobs with 2 slots: a multi-agent job never shares
    # the machine (its wall-clock is compared), the light ones may run together.
    import sys

    import ials_zoo.reproduce.runner as runner
    from ials_zoo.reproduce.plan import Job

    log = tmp_path / "log.txt"
    script = ("import sys, time, pathlib; d = pathlib.Path(sys.argv[1]).parent; "
              f"open({str(log)!r}, 'a').write(f'start {{d.name}} {{time.time()}}\\n'); time.sleep(0.4); "
              f"open({str(log)!r}, 'a').write(f'end {{d.name}} {{time.time()}}\\n'); (d / 'done').write_text('x')")
    monkeypatch.setattr(runner, "_command", lambda job_file: [sys.executable, "-c", script, str(job_file)])
    jobs = [Job(id=f"j{i}", kind=kind, dir=str(tmp_path / f"j{i}"), marker="done", params={"seed": 0})
            for i, kind in enumerate(["multiagent", "joint-reference", "joint-reference", "multiagent"])]
    status = runner.run_jobs(jobs, n_jobs=2, progress=False, poll=0.05)
    assert sorted(status["done"]) == ["j0", "j1", "j2", "j3"]
    spans = {}
    for line in log.read_text().split("\n"):
        if line:
            what, name, t = line.split()
            spans.setdefault(name, {})[what] = float(t)
    for ex in ("j0", "j3"):
        for other, s in spans.items():
            if other != ex:
                overlap = min(s["end"], spans[ex]["end"]) - max(s["start"], spans[ex]["start"])
                assert overlap <= 0, f"{other} ran while the exclusive {ex} did"
    assert min(spans["j1"]["end"], spans["j2"]["end"]) > max(spans["j1"]["start"], spans["j2"]["start"])


def _multi_run(root, label, seed, score, seconds, aip, workers=2, algorithm="dials"):
    d = root / "dials" / "warehouse_v0" / f"{label.replace(' ', '_')}__s{seed}"
    (d / "run").mkdir(parents=True)
    params = {"algorithm": algorithm, "env_id": "warehouse_v0", "seed": seed, "total_timesteps": 1000}
    if algorithm == "dials":
        params["workers"] = workers
    (d / "job.json").write_text(json.dumps({"kind": "multiagent", "label": label, "params": params}))
    result = {"score": {"mean": score}, "policy": {"name": "p"},
              "training": {"wall_clock_seconds": seconds, "aip_seconds": aip, "env_steps": 1000}}
    (d / "run" / "result.json").write_text(json.dumps(result))
    (d / "run" / "curve.json").write_text(json.dumps(
        {"points": [{"wall_clock_seconds": aip, "mean": 0.0}, {"wall_clock_seconds": aip + seconds, "mean": score}]}))


def test_dials_summary_targets_and_parallel_efficiency(tmp_path):
    from ials_zoo.reproduce.claims import dials_claims, load_multiagent_runs, summarize_dials
    from ials_zoo.reproduce.report import write_dials_report

    for seed, (a, b, c) in enumerate([(10.0, 9.8, 3.0), (10.4, 10.2, 3.2)]):
        _multi_run(tmp_path, "ippo", seed, a, 100.0, 0.0, algorithm="ippo")
        _multi_run(tmp_path, "dials", seed, b, 30.0, 10.0)
        _multi_run(tmp_path, "untrained-dials", seed, c, 30.0, 0.0)
    _multi_run(tmp_path, "dials (1 worker)", 0, 9.8, 50.0, 10.0, workers=1)
    summary = summarize_dials(load_multiagent_runs(tmp_path))["warehouse_v0"]
    v = summary["variants"]
    assert list(v) == ["ippo", "dials", "untrained-dials", "dials (1 worker)"]
    assert v["dials"]["score_ratio_to_ippo"] == pytest.approx(10.0 / 10.2)
    assert v["dials"]["time_ratio_to_ippo"] == pytest.approx(0.4)
    par = summary["parallel"]
    assert par["speedup"] == pytest.approx(60 / 40) and par["efficiency"] == pytest.approx(0.75)
    assert par["train_speedup"] == pytest.approx(50 / 30) and par["same_score"]
    claims = {(c["id"], c.get("label")): c for c in dials_claims(summary)}
    assert claims[("score", "dials")]["holds"] and claims[("time", "dials")]["holds"]
    assert claims[("untrained_worse", None)]["holds"]
    assert claims[("score", "dials-once")]["holds"] is None  # not run: not measured
    text = write_dials_report(tmp_path, tmp_path / "lb").read_text()
    assert "speed-up 1.50, efficiency 0.75" in text and "ratio 0.40 -> holds" in text


@pytest.mark.parametrize("env_id", ["warehouse_v0", "traffic_grid_v0"])
def test_shipped_aip_sets_cover_every_agent_and_load_without_training(env_id, monkeypatch):
    from ials_zoo.core.domains import get_domain
    from ials_zoo.influence import multi
    from ials_zoo.influence.files import load_predictor_set

    domain = get_domain(env_id)
    path = multi.shipped_set_path(env_id)
    found = load_predictor_set(path, env_id=env_id)
    assert sorted(found) == sorted(domain.possible_agents())
    for agent, pred in found.items():
        assert pred.region == domain.region_spec(agent)
    # "trained" resolves to the shipped set: nothing is collected or trained
    monkeypatch.setattr("ials_zoo.influence.dataset.collect_all",
                        lambda *a, **k: (_ for _ in ()).throw(AssertionError("collected data")))
    got = multi.trained_predictor_set(env_id, train_if_missing=False, progress=False)
    assert sorted(got) == sorted(found)
