"""Reporting the way the field reports: IQM, stratified bootstrap intervals and the
probability of improvement (scipy) against rliable's definitions, and the board's marl-eval
export against marl-eval's documented format."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from ials_zoo.stats import iqm, iqm_interval, probability_of_improvement

rliable_metrics = pytest.importorskip("rliable.metrics")


def test_iqm_is_rliables_aggregate_iqm():
    rng = np.random.default_rng(0)
    for n in (5, 8, 10, 13):
        scores = rng.normal(100, 20, size=(n, 1))
        assert iqm(scores[:, 0]) == pytest.approx(rliable_metrics.aggregate_iqm(scores), rel=1e-12)
    # two tasks: the IQM of all the scores together, as rliable's aggregate over a run x task matrix
    scores = rng.normal(0, 1, size=(10, 2))
    assert iqm(scores.ravel()) == pytest.approx(rliable_metrics.aggregate_iqm(scores), rel=1e-12)


def test_probability_of_improvement_is_rliables():
    rng = np.random.default_rng(1)
    x, y = rng.normal(1.0, 1.0, 10), rng.normal(0.0, 1.0, 7)
    p, lo, hi = probability_of_improvement(x, y)
    assert p == pytest.approx(rliable_metrics.probability_of_improvement(x[:, None], y[:, None]), rel=1e-12)
    assert lo <= p <= hi and 0.0 <= lo and hi <= 1.0
    # ties count a half; identical samples are a coin toss
    assert probability_of_improvement([1.0, 2.0], [1.0, 2.0])[0] == pytest.approx(0.5)
    assert probability_of_improvement([3.0, 4.0], [1.0, 2.0])[0] == 1.0


def test_the_iqm_interval_resamples_within_each_task():
    """Task 1's seeds all score 1, task 2's score 10 or 11: resampled within each task, the
    IQM of 8 scores stays in [5.5, 6]; resampled across tasks it would reach 1 and 10."""
    point, lo, hi = iqm_interval([[1.0, 1.0, 1.0, 1.0], [10.0, 10.0, 10.0, 11.0]])
    assert point == 5.5 and lo >= 5.5 and hi <= 6.0
    # one task: a plain bootstrap of the IQM, which covers the point and lies inside the data
    rng = np.random.default_rng(2)
    x = rng.normal(5.0, 1.0, 10)
    point, lo, hi = iqm_interval([x])
    assert x.min() <= lo <= point <= hi <= x.max() and hi - lo > 0.1


def test_marl_eval_export_has_marl_evals_documented_shape(tmp_path):
    """env -> task -> algorithm -> run -> step_i {step_count, metric lists} + absolute_metrics,
    for every trained official entry of the shipped board."""
    out = tmp_path / "board.json"
    proc = subprocess.run([sys.executable, "-m", "ials_zoo.cli", "leaderboard", "export", "--format", "marl-eval",
                           "--out", str(out)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    data = json.loads(out.read_text())
    assert set(data) == {"traffic_grid_v0", "warehouse_v0", "sumo_net_v0"}
    assert "25-agents" in data["traffic_grid_v0"] and "36-agents" in data["warehouse_v0"]
    assert {"net=cologne8/8-agents", "net=grid4x4/16-agents"} <= set(data["sumo_net_v0"])  # a task per map
    runs_seen = 0
    for tasks in data.values():
        for algorithms in tasks.values():
            assert not any(a.startswith(("scripted", "random")) for a in algorithms)
            for runs in algorithms.values():
                for run_name, run in runs.items():
                    assert run_name.startswith("run_")
                    steps = sorted((k for k in run if k.startswith("step_")), key=lambda k: int(k[5:]))
                    assert steps and set(run) == set(steps) | {"absolute_metrics"}
                    counts = [run[k]["step_count"] for k in steps]
                    assert all(isinstance(c, int) for c in counts) and counts == sorted(counts)
                    for k in steps:
                        assert isinstance(run[k]["episode_return"], list) and len(run[k]["episode_return"]) >= 1
                    assert len(run["absolute_metrics"]["episode_return"]) == 20  # the protocol's episodes
                    runs_seen += 1
    assert runs_seen >= 20


def test_export_refuses_an_unknown_format():
    proc = subprocess.run([sys.executable, "-m", "ials_zoo.cli", "leaderboard", "export", "--format", "csv"],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "csv" in proc.stderr


def test_marl_eval_keeps_apart_two_entries_of_one_algorithm_on_one_task():
    """Two trained entries of one algorithm on one task (other settings, the same seeds) are two
    algorithms of the export, each named by its entry id: neither seed overwrites the other's."""
    from ials_zoo.leaderboard.export import marl_eval

    def entry(value):
        return {"env_id": "warehouse_v0", "track": "multi-agent", "agents": ["a", "b"], "algorithm": "ippo",
                "training": {"simulator": "gs"}, "policy": {"kind": "model"}, "learning_curves": [],
                "evaluation": {"protocol": "official", "options": {}, "deterministic": False},
                "scores": [{"seed": 0, "returns": [value], "metrics": {}}]}

    out = marl_eval([("r/warehouse_v0__2-agents__ippo__gs__aaa.json", entry(1.0)),
                     ("r/warehouse_v0__2-agents__ippo__gs__bbb.json", entry(2.0)),
                     ("r/warehouse_v0__2-agents__dials__dials__ccc.json", dict(entry(3.0), algorithm="dials"))])
    algorithms = out["warehouse_v0"]["2-agents"]
    assert sorted(algorithms) == ["dials/gs", "ippo/gs/aaa", "ippo/gs/bbb"]
    assert algorithms["ippo/gs/aaa"]["run_0"]["absolute_metrics"]["episode_return"] == [1.0]
    assert algorithms["ippo/gs/bbb"]["run_0"]["absolute_metrics"]["episode_return"] == [2.0]
