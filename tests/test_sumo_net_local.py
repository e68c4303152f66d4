"""The local simulators of every region of a real network (cologne8) as one ParallelEnv: the
GS's agents and spaces, PettingZoo's API, and the GS's recorded inflow inserted at its rate."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from ials_zoo.sumo_net.env import SumoNetEnv
from ials_zoo.sumo_net.local import GSInfluence, LocalNetEnv


@pytest.fixture(scope="module")
def local():
    env = LocalNetEnv(net="cologne8", max_cycles=30, record_seconds=600)
    yield env
    env.close()


def test_a_local_env_has_the_gs_agents_and_spaces_and_passes_the_api_test(local):
    gs = SumoNetEnv(net="cologne8", max_cycles=30)
    try:
        assert local.possible_agents == gs.possible_agents
        for a in gs.possible_agents:
            assert local.observation_space(a) == gs.observation_space(a)
            assert local.action_space(a) == gs.action_space(a)
    finally:
        gs.close()
    parallel_api_test(local, num_cycles=30)


def test_the_recorded_inflow_is_inserted_at_its_rate(local):
    rng = np.random.default_rng(0)
    local.reset(seed=5)
    before = local._sim.call("inserted_total")
    steps = 0
    while local.agents:
        obs, *_ = local.step({a: int(rng.integers(local.action_space(a).n)) for a in local.agents})
        steps += local.scenario.decision_seconds
    inserted = local._sim.call("inserted_total") - before
    expected = local.influence.rate() * steps  # 300 SUMO steps: the Poisson-like spread is ~7%
    assert 0.75 * expected < inserted < 1.25 * expected, (inserted, expected)


def test_influence_is_grouped_by_light_and_step():
    steps = [[("a", "v1", ("e",), 0, 1.0, 5.0, "car", 1.0)], [], [("b", "v2", ("f", "g"), 1, 0.0, 0.0, "car", 0.9),
                                                                 ("a", "v3", ("e",), 0, 2.0, 4.0, "car", 1.1)]]
    g = GSInfluence(steps, ["a", "b"])
    assert g.steps["a"] == [[("v1", ("e",), 0, 1.0, 5.0, "car", 1.0)], [], [("v3", ("e",), 0, 2.0, 4.0, "car", 1.1)]]
    assert g.steps["b"] == [[], [], [("v2", ("f", "g"), 1, 0.0, 0.0, "car", 0.9)]]
    assert g.rate() == pytest.approx(1.0)
