"""The libraries our users run: TorchRL (and so BenchMARL), RLlib, PettingZoo's own tests."""

import subprocess
import sys

import pytest

from ials_zoo import traffic_grid_v0, warehouse_v0

SMALL = {warehouse_v0: {"robots": (2, 2), "max_cycles": 20}, traffic_grid_v0: {"grid": (2, 2), "max_cycles": 20}}


@pytest.mark.parametrize("module", [warehouse_v0, traffic_grid_v0], ids=["warehouse", "traffic"])
def test_torchrl_pettingzoo_wrapper_and_specs(module):
    pytest.importorskip("torchrl")
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs

    env = PettingZooWrapper(env=module.parallel_env(**SMALL[module]), return_state=True, use_mask=False)
    try:
        check_env_specs(env)
        td = env.rollout(5)
        assert "state" in td.keys() and td.batch_size[0] == 5
    finally:
        env.close()


def test_rllib_trains_one_iteration_on_the_gs():
    ray = pytest.importorskip("ray")
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
    from ray.tune.registry import register_env

    register_env("ials_zoo_warehouse_small", lambda cfg: ParallelPettingZooEnv(warehouse_v0.parallel_env(**SMALL[warehouse_v0])))
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, ignore_reinit_error=True)
    try:
        agents = [f"robot_{i}" for i in range(4)]
        config = (PPOConfig().environment("ials_zoo_warehouse_small").env_runners(num_env_runners=0)
                  .multi_agent(policies=set(agents), policy_mapping_fn=lambda aid, *a, **k: aid)
                  .training(train_batch_size_per_learner=80, minibatch_size=40, num_epochs=1)
                  .rl_module(model_config={"fcnet_hiddens": [8]}))
        algo = config.build_algo()
        result = algo.train()
        assert result["env_runners"]["num_env_steps_sampled_lifetime"] >= 80
        algo.stop()
    finally:
        ray.shutdown()


def test_libsumo_pyarrow_warning_is_silenced():
    """Ray installs pyarrow; libsumo then warns at every import, about outputs we never use."""
    code = ("from ials_zoo.traffic.env import TrafficGridEnv; e = TrafficGridEnv(grid=(2, 2)); "
            "e.reset(seed=0); e.close(); import os; print(os.environ.get('LIBSUMO_AS_TRACI'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "pyarrow" not in out.stdout + out.stderr
    assert out.stdout.strip() == "None"  # the switch is not left set (it would turn traci into libsumo)
