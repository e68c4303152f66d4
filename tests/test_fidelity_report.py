"""The fidelity report: its metrics on hand-made influence sequences, the GS's own physics
under a lingering joint policy, and the command end to end on a short run."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ials_zoo.cli import main
from ials_zoo.errors import BadInput
from ials_zoo.influence.fidelity import compare, episode_metrics


def test_episode_metrics_by_hand():
    null = 3
    # one source: a neighbour stays 3 steps on cell 0, moves to cell 1 for 1 step, leaves,
    # comes back to cell 2 for 2 steps; a second source never active
    u = np.array([[3, 3], [0, 3], [0, 3], [0, 3], [1, 3], [3, 3], [2, 3], [2, 3]])
    m = episode_metrics(u, null)
    assert m["active"] == pytest.approx(6 / 16)
    # active at t-1 and equal at t: (0,0), (0,0), (2,2) of the active previous steps 1,2,3,4,6
    assert m["persistence"] == pytest.approx(3 / 5)
    assert m["arrivals"] == 3  # cell 0 at t=1, cell 1 at t=4, cell 2 at t=6
    assert m["run_length"] == pytest.approx((3 + 1 + 2) / 3)
    assert m["gap"] == pytest.approx(((4 - 1) + (6 - 4)) / 2)
    quiet = episode_metrics(np.full((5, 2), 3), null)
    assert quiet["arrivals"] == 0 and math.isnan(quiet["persistence"]) and math.isnan(quiet["gap"])


def test_compare_holds_within_the_sampling_error_only():
    rng = np.random.default_rng(0)
    a, b = rng.normal(1.0, 0.1, 30), rng.normal(1.0, 0.1, 30)
    assert compare(a, b, tolerance=0.0)["holds"]
    assert not compare(a, b + 0.5, tolerance=0.1)["holds"]
    assert compare(a, b + 0.05, tolerance=0.1)["holds"]  # within 10% of the GS value


def test_the_report_runs_and_the_gs_lingers_under_a_constant_policy(tmp_path, capsys):
    """Every robot always moves up: it reaches its top shelf cell and stays there, so on the GS
    each watched robot's upper neighbour source is active from one arrival to the end."""
    out = tmp_path / "f.md"
    assert main(["fidelity", "--env", "warehouse_v0", "--episodes", "2", "--policies", "constant,scripted",
                 "--agents", "robot_20", "--out", str(out)]) == 0
    text = out.read_text()
    assert "| robot_20 | persistence | 1.000 |" in text and "| robot_20 | arrivals | 1.000 |" in text
    assert "scripted controllers have no IALS form" in text
    assert main(["fidelity", "--env", "warehouse_v0", "--episodes", "1"]) == 2


def test_on_policy_autoregressive_aips_keep_a_random_neighbour_lingering():
    """Under uniformly random robots a neighbour on a shared cell stays there at the next step
    with probability about 0.75 on the GS. AIPs trained on that policy's GS data that read their
    own last draw, trained long enough (60 epochs here, the rate decaying to zero; at 10 they
    reach 0.42 against 0.73), keep it (within 0.1) and arrive about as often as the GS's
    neighbours; memoryless ones (the paper's) redraw every step, about 0.05."""
    from ials_zoo.influence.fidelity import fidelity_report

    kw = dict(episodes=6, watched=["robot_0"], progress=False, collect_steps=5000, aip_lr=1e-2, robots=(2, 2))
    ar = fidelity_report("warehouse_v0", ["random"], predictor="on-policy-autoregressive", aip_epochs=60, **kw)
    memoryless = fidelity_report("warehouse_v0", ["random"], predictor="on-policy", aip_epochs=10, **kw)
    ar_m, ml_p = ar["policies"]["random"]["robot_0"], memoryless["policies"]["random"]["robot_0"]["persistence"]
    assert 0.65 < ar_m["persistence"]["gs"] < 0.85, ar_m
    assert abs(ar_m["persistence"]["ials"] - ar_m["persistence"]["gs"]) < 0.1, ar_m
    assert 0.6 < ar_m["arrivals"]["ials"] / ar_m["arrivals"]["gs"] < 1.4, ar_m
    assert ml_p["ials"] < 0.2, ml_p
    assert (ar["predictor"], ar["aip_lr"], ar["aip_epochs"], ar["aip_lr_schedule"]) == (
        "on-policy-autoregressive", 1e-2, 60, "linear")


def test_on_policy_aips_train_at_the_domains_fidelity_settings(monkeypatch):
    """Without --aip-lr/--aip-epochs/--aip-lr-schedule the on-policy AIPs train at the domain's
    fidelity settings (longer than DIALS's budget), and the report says so."""
    from ials_zoo.core.extras import dials_of
    from ials_zoo.errors import BadInput
    from ials_zoo.influence import fidelity
    from ials_zoo.influence.fidelity import markdown, on_policy_training

    d = dials_of("warehouse_v0")
    assert on_policy_training("warehouse_v0", True) == (d.fidelity_aip_lr, d.fidelity_aip_epochs,
                                                        d.fidelity_aip_lr_schedule, d.fidelity_aip_influence_lags)
    assert d.fidelity_aip_epochs > d.aip_epochs
    assert on_policy_training("warehouse_v0", True, 1e-2, 7, "constant", 2) == (1e-2, 7, "constant", 2)
    assert on_policy_training("warehouse_v0", False)[3] == 0  # memoryless AIPs read no lags
    for bad in (dict(lr=0.0), dict(lr=float("nan")), dict(epochs=0), dict(epochs=True), dict(lr_schedule="cosine"),
                dict(influence_lags=0), dict(influence_lags=1.5)):
        with pytest.raises(BadInput):
            on_policy_training("warehouse_v0", True, **bad)
    with pytest.raises(BadInput, match="autoregressive"):
        on_policy_training("warehouse_v0", False, influence_lags=2)
    with pytest.raises(BadInput, match="aip_lr_schedule"):
        d.__class__(aip_lr_schedule="step")
    for bad in (dict(fidelity_aip_influence_lags=0), dict(fidelity_collect_steps=0)):
        with pytest.raises(BadInput, match=next(iter(bad))):
            d.__class__(**bad)
    # a domain without fidelity settings falls back to DIALS's own AIP training
    toy = dials_of("traffic_grid_v0").__class__(aip_lr=5e-4, aip_epochs=3, aip_autoregressive_lr=2e-2,
                                                fidelity_aip_lr_schedule=None)
    monkeypatch.setattr(fidelity, "dials_of", lambda env_id: toy)
    assert fidelity.on_policy_training("any", True) == (2e-2, 3, "constant", 1)
    assert fidelity.on_policy_training("any", False) == (5e-4, 3, "constant", 0)
    report = {"env_id": "warehouse_v0", "episodes": 2, "tolerance": 0.1, "predictor": "on-policy-autoregressive",
              "aip_lr": 3e-3, "aip_epochs": 120, "aip_lr_schedule": "linear", "policies": {}}
    assert "lr 0.003 decayed linearly to 0, 120 epochs" in markdown(report)
    assert "lr 0.01 (constant), 10 epochs" in markdown(dict(report, aip_lr=1e-2, aip_epochs=10,
                                                           aip_lr_schedule="constant"))
    assert "reading their last 3 draws, trained on 100,000 GS steps of each policy" in markdown(
        dict(report, aip_influence_lags=3, collect_steps=100_000))
    with pytest.raises(BadInput, match="aip_lr_schedule"):
        fidelity.fidelity_report("warehouse_v0", ["random"], episodes=2, aip_lr_schedule="cosine")


def test_several_aip_trainings_count_the_rows_that_hold_under_each():
    """With aip_seeds=2 the first training's comparison is exactly the single-training report's,
    the second training differs (other data, other weights), and ``holds_in`` counts the
    trainings under which each row holds."""
    from ials_zoo.influence.fidelity import fidelity_report, markdown

    kw = dict(episodes=3, watched=["robot_0"], progress=False, collect_steps=1000, aip_lr=1e-2, aip_epochs=2,
              robots=(2, 2), predictor="on-policy-autoregressive")
    one = fidelity_report("warehouse_v0", ["random"], **kw)["policies"]["random"]["robot_0"]
    two = fidelity_report("warehouse_v0", ["random"], aip_seeds=2, **kw)
    rows = two["policies"]["random"]["robot_0"]
    for metric, row in rows.items():
        assert {k: row[k] for k in ("gs", "ials", "low", "high", "holds")} == \
            {k: one[metric][k] for k in ("gs", "ials", "low", "high", "holds")}, metric
        assert row["per_training"][0] == row["holds"] and len(row["per_training"]) == 2
        assert row["holds_in"] == sum(h for h in row["per_training"] if h is not None)
    # the second training ran other AIPs (other data and seeds): its IALS side is not the first's
    assert any(row["ials_per_training"][0] != row["ials_per_training"][1] for row in rows.values())
    assert all(row["ials_per_training"][0] == row["ials"] or row["ials"] != row["ials"] for row in rows.values())
    text = markdown(two)
    assert "2 trainings" in text
    for metric, row in rows.items():
        line = next(x for x in text.splitlines() if x.startswith(f"| robot_0 | {metric} |"))
        if row["holds_in"] is None:
            assert line.endswith("| - |"), line
        else:
            cell = f"{row['holds_in']} / {row['trainings_compared']}"
            assert line.endswith(f"| {cell} |" if row["holds_in"] == row["trainings_compared"] else f"| **{cell}** |"), line
    from ials_zoo.errors import BadInput

    with pytest.raises(BadInput, match="aip_seeds"):
        fidelity_report("warehouse_v0", ["random"], episodes=2, predictor="uniform", aip_seeds=2, robots=(2, 2))


def test_traffic_on_policy_aips_read_their_last_three_draws_and_a_clock(monkeypatch):
    """Traffic's fidelity AIPs read their last 3 draws and a clock of 100 steps (the domain's
    fidelity_aip_influence_lags and fidelity_aip_clock_horizon), and the multi-agent IALS
    samples them on SUMO; the report states the lags, the clock and the data."""
    from ials_zoo.influence import fidelity

    trained = []
    real = fidelity.train_predictors

    def spy(*args, **kwargs):
        preds, report = real(*args, **kwargs)
        trained.append(preds)
        return preds, report

    monkeypatch.setattr(fidelity, "train_predictors", spy)
    report = fidelity.fidelity_report("traffic_grid_v0", ["random"], episodes=2, watched=["tls_0"], progress=False,
                                      collect_steps=600, aip_epochs=1, predictor="on-policy-autoregressive")
    assert (report["aip_influence_lags"], report["aip_clock_horizon"], report["collect_steps"]) == (3, 100, 600)
    assert {(p.influence_lags, p.clock_horizon) for p in trained[0].values()} == {(3, 100)}
    assert trained[0]["tls_0"].input_size == 36 + 3 * 4 * 2 + 1
    arrivals = report["policies"]["random"]["tls_0"]["arrivals"]
    assert arrivals["gs"] > 0 and arrivals["ials"] > 0
    assert ("reading their last 3 draws, reading a clock (min(t, 100) / 100), trained on 600 GS steps"
            in fidelity.markdown(report))


def test_a_cycle_plan_holds_each_action_h_steps_per_agent_and_restarts():
    """cycle:H, a fixed-time plan: every agent steps through its own actions, H steps each."""
    from ials_zoo.core.spaces import JointSizes
    from ials_zoo.influence.fidelity import _joint_policy

    sizes = JointSizes(obs_size=4, n_actions=3, action_counts=(2, 3))
    plan = _joint_policy("cycle:2", sizes, 2)
    seen = [plan.act_all(None).tolist() for _ in range(7)]
    assert seen == [[0, 0], [0, 0], [1, 1], [1, 1], [0, 2], [0, 2], [1, 0]]
    plan.reset(5)
    assert plan.act_all(None).tolist() == [0, 0]
    for bad in ("cycle:0", "cycle:x", "cycle:"):
        with pytest.raises(BadInput, match="cycle:H"):
            _joint_policy(bad, sizes, 2)
    assert main(["fidelity", "--env", "warehouse_v0", "--policies", "cycle:-1"]) == 2


def test_the_report_opens_with_how_many_agents_hold_per_metric():
    from ials_zoo.influence.fidelity import METRICS, markdown

    def row(holds):
        return {"gs": 1.0, "ials": 1.0, "low": -1.0, "high": 1.0, "holds": holds}

    agents = {"a": {k: row(True) for k in METRICS}, "b": {k: row(k != "gap") for k in METRICS}}
    agents["b"]["return"] = row(None)  # not comparable (no values): not counted
    report = {"env_id": "x", "episodes": 2, "tolerance": 0.1, "policies": {"random": agents, "scripted": {"gs_only": {}}}}
    summary = markdown(report).split("**random**")[0]
    cells = {k: c.strip() for k, c in zip(METRICS, summary.split("| random |")[1].split("\n")[0].split("|"))}
    assert cells["gap"] == "1 / 2" and cells["active"] == "2 / 2" and cells["return"] == "1 / 1"
    assert "| scripted |" not in summary
