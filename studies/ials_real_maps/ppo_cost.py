"""PPO's own cost in an ingolstadt21 IPPO or DIALS run, with no simulator: 21 agents (input 70,
4 actions), the runs' settings (512 samples per agent per update over 2 copies, 10 epochs,
minibatch 128, 64-64 layers), acting and updating over the whole budget of 70 updates on random
data. Whatever a faster simulator saves, a run of this budget cannot take less (docs/sumo_net.md,
"One quiet machine").

Usage: python studies/ials_real_maps/ppo_cost.py [UPDATES]   (default 70, the whole budget)
"""

import sys
import time

import numpy as np
import torch

from ials_zoo.learners.batched_ppo import BatchedPPO, PPOConfig

AGENTS, INPUT, ACTIONS, COPIES, STEPS, BUDGET = 21, 70, 4, 2, 256, 70


def main(updates: int) -> None:
    torch.set_num_threads(1)
    cfg = PPOConfig(n_steps=STEPS, n_envs=COPIES, batch_size=128, n_epochs=10, learning_rate=1e-3,
                    anneal_lr=False, gamma=0.95, hidden=(64, 64), normalize_reward=True)
    ppo = BatchedPPO([f"a{i}" for i in range(AGENTS)], INPUT, ACTIONS, cfg, seed=0, total_updates=BUDGET)
    rng, n = np.random.default_rng(0), STEPS * COPIES
    obs = rng.random((AGENTS, COPIES, INPUT)).astype(np.float32)
    acting = updating = 0.0
    for _ in range(updates):
        start = time.perf_counter()
        for _ in range(STEPS):
            ppo.act(obs)
        acting += time.perf_counter() - start
        batch = dict(obs=rng.random((AGENTS, n, INPUT)).astype(np.float32),
                     actions=rng.integers(0, ACTIONS, (AGENTS, n)),
                     logp_old=np.full((AGENTS, n), -np.log(ACTIONS), np.float32),
                     returns=rng.standard_normal((AGENTS, n)).astype(np.float32),
                     advantages=rng.standard_normal((AGENTS, n)).astype(np.float32),
                     values_old=np.zeros((AGENTS, n), np.float32))
        start = time.perf_counter()
        ppo.update(**batch)
        updating += time.perf_counter() - start
    scale = BUDGET / updates
    print(f"{updates} updates timed; over the budget of {BUDGET}: acting {acting * scale:.0f} s, "
          f"updating {updating * scale:.0f} s, PPO in all {(acting + updating) * scale:.0f} s")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else BUDGET)
