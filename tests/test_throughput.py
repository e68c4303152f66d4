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
