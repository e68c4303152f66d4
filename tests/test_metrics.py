"""Physical metrics beside the return, each checked against a reference computed another way:
the warehouse's from snapshots of the floor's item ages, the traffic grid's from per-vehicle
libsumo queries."""

from __future__ import annotations

import numpy as np
import pytest

from ials_zoo.core.domains import get_domain


def test_warehouse_metrics_match_the_floor_seen_step_by_step():
    env = get_domain("warehouse_v0").parallel_env(robots=(3, 3))
    env.reset(seed=4)
    env.enable_metrics()
    rng = np.random.default_rng(0)
    collected, ages, waiting, steps = 0, [], [], 0
    before = env.item_ages_floor()
    while env.agents:
        env.step({a: int(rng.integers(4)) for a in env.agents})
        after = env.item_ages_floor()
        # without a lifetime items leave only when collected; a collected cell may get a new
        # item (age 1) at once, where an uncollected one would be 2 or older
        taken = (before > 0) & (after <= 1)
        collected += int(taken.sum())
        ages += before[taken].tolist()
        waiting.append(int((after > 0).sum()))
        before = after
        steps += 1
    got = env.episode_metrics()
    assert collected > 20
    assert got["items_per_robot"] == pytest.approx(collected / 9)
    assert got["age_at_collection"] == pytest.approx(np.mean(ages))
    assert got["items_waiting"] == pytest.approx(np.mean(waiting) / 9)


def test_traffic_metrics_match_per_vehicle_queries():
    """Arrivals, time loss and waiting time of arrived vehicles (SUMO's tripinfo device) and
    the halting vehicles on the incoming lanes, against libsumo's per-vehicle getters."""
    from ials_zoo.traffic import network

    domain = get_domain("traffic_grid_v0")
    env = domain.parallel_env(grid=(2, 2), max_cycles=150)
    try:
        env.reset(seed=3)
        env.enable_metrics()
        rng = np.random.default_rng(1)
        incoming = {e + "_0" for i in range(4) for e in network.incoming_edges((2, 2), i)}
        last_loss, last_wait, seen, arrived, halting = {}, {}, set(), 0, []
        while env.agents:
            env.step({a: int(rng.integers(2)) for a in env.agents})
            ids = set(env.sumo_query("vehicle", "getIDList"))
            arrived += env.sumo_query("simulation", "getArrivedNumber")
            gone = seen - ids
            for v in ids:
                last_loss[v] = env.sumo_query("vehicle", "getTimeLoss", v)
                last_wait[v] = env.sumo_query("vehicle", "getAccumulatedWaitingTime", v)
            seen = (seen - gone) | ids
            lanes = {v: env.sumo_query("vehicle", "getLaneID", v) for v in ids}
            speeds = {v: env.sumo_query("vehicle", "getSpeed", v) for v in ids}
            halting.append(sum(1 for v in ids if speeds[v] < 0.1 and lanes[v] in incoming))
        got = env.episode_metrics()
        finished = [v for v in last_loss if v not in seen]
        assert arrived == len(finished) > 10
        assert got["throughput"] == arrived
        # tripinfo adds the arrival step's own loss: within a second of the last reading
        assert got["delay"] == pytest.approx(np.mean([last_loss[v] for v in finished]), abs=1.0)
        assert got["waiting_time"] == pytest.approx(np.mean([last_wait[v] for v in finished]), abs=1.0)
        assert got["queue"] == pytest.approx(np.mean(halting), rel=1e-9)
    finally:
        env.close()


@pytest.mark.parametrize("env_id", ["warehouse_v0", "traffic_grid_v0"])
def test_every_evaluation_carries_the_domains_metrics(env_id):
    from ials_zoo.evaluation import evaluate_joint
    from ials_zoo.leaderboard import make_result, validate_result
    from ials_zoo.leaderboard.validate import ResultError

    options = {"robots": (2, 2)} if env_id == "warehouse_v0" else {"grid": (2, 2), "max_cycles": 60}
    ev = evaluate_joint(env_id, "scripted", episodes=3, **options)
    assert set(ev.metrics) == set(get_domain(env_id).metrics)
    for m in ev.metrics.values():
        assert m["ci_low"] <= m["mean"] <= m["ci_high"]
    result = validate_result(make_result([ev], algorithm="scripted"))
    assert result["metrics"] == result["scores"][0]["metrics"]
    forged = dict(result, metrics={**result["metrics"], "speed_of_light": {"mean": 1.0, "ci_low": 0.0, "ci_high": 2.0}})
    with pytest.raises(ResultError, match="speed_of_light"):
        validate_result(forged)
    name = next(iter(result["metrics"]))
    shifted = {**result["metrics"], name: {k: v + 1.0 for k, v in result["metrics"][name].items()
                                           if k in ("mean", "ci_low", "ci_high")}}
    with pytest.raises(ResultError, match="metrics"):
        validate_result(dict(result, metrics=shifted))
