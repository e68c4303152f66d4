"""PPO throughput measurement (``ials-zoo bench --ppo``): the free vec env and the floor."""

import numpy as np
import pytest
from gymnasium import spaces

from ials_zoo.baselines.throughput import NO_SIMULATOR, FreeVecEnv, ppo_bound, ppo_throughput


def test_free_vec_env_truncates_every_episode_at_its_length():
    env = FreeVecEnv(3, spaces.Box(0, 1, (5,), np.float32), spaces.Discrete(2), episode_length=4)
    obs = env.reset()
    assert obs.shape == (3, 5) and not obs.any()
    for t in range(1, 9):
        env.step_async(np.zeros(3, dtype=np.int64))
        obs, rew, dones, infos = env.step_wait()
        assert not rew.any()
        assert dones.all() == (t % 4 == 0) and dones.any() == (t % 4 == 0)
        if t % 4 == 0:
            assert all(i["TimeLimit.truncated"] and i["terminal_observation"].shape == (5,) for i in infos)


def test_ppo_throughput_runs_the_baselines_ppo_on_each_simulator():
    rows = [ppo_throughput("warehouse_v0", "robot_20", sim, steps=2048, n_envs=2) for sim in ("gs", NO_SIMULATOR)]  # one update
    for r in rows:
        assert r["steps"] == 2048 and r["steps_per_s"] > 0 and r["n_envs"] == 2
    bound = ppo_bound(rows)
    assert bound["time_per_step_vs_gs"]["gs"] == 1.0
    assert bound["floor"] == bound["time_per_step_vs_gs"][NO_SIMULATOR] > 0
    with pytest.raises(ValueError, match="'none' row"):
        ppo_bound(rows[:1])
    with pytest.raises(ValueError, match="unknown agent"):
        ppo_throughput("warehouse_v0", "robot_99", "gs", steps=10)


def test_the_bench_says_what_to_take_from_its_figures():
    """The conclusion lines read the medians: which API is cheaper than the GS and by how
    much, and what the two ratios mean."""
    from ials_zoo.bench.report import conclusion

    def s(m):
        return {"median": m, "min": m, "max": m}

    row = {"batch": 32, "single_agent": {"ials_vs_gs_speed": s(7.0), "ials_batched_vs_gs_speed": s(40.0)},
           "every_agent": {"ials_parallel_env_cost_vs_gs": s(2.4), "ials_dials_cost_vs_gs": s(0.6)},
           "learner": {"update_cost_vs_previous": s(3.1)}}
    text = "\n".join(conclusion(row))
    assert "7.0x as fast as the GS, 40.0x batched" in text
    assert "costs 0.60x the GS per agent-step, cheaper than it" in text and "costs 2.40x" in text
    row["every_agent"]["ials_dials_cost_vs_gs"] = s(1.3)
    assert "costs 1.30x the GS per agent-step, dearer than it" in "\n".join(conclusion(row))
    assert "the compatible API, not the fast one" in text
    row["every_agent"]["ials_parallel_env_cost_vs_gs"] = s(1.35)
    assert "about the same here" in "\n".join(conclusion(row))
    assert "within each repeat" in text and "3.10x per sample" in text
