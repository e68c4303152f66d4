"""The fidelity report: its metrics on hand-made influence sequences, the GS's own physics
under a lingering joint policy, and the command end to end on a short run."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ials_zoo.cli import main
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
