"""The warehouse as a zoo domain: what generic code needs to know about it."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from ials_zoo.core.domains import Domain
from ials_zoo.core.extras import BenchSettings, DIALSSettings, StudySettings, ViewerSettings
from ials_zoo.warehouse import regions as R
from ials_zoo.warehouse import render
from ials_zoo.warehouse.env import parallel_env
from ials_zoo.warehouse.local import local_simulator


def episode_summary(env) -> dict[str, str]:
    """Items collected by all robots, and the mean return of learners and scripted robots."""
    returns = np.asarray(env.episode_returns, dtype=float)
    learners = np.zeros(len(returns), bool)
    learners[env.learner_indices] = True
    out = {"items collected (all robots)": str(env.items_collected),
           "mean return, learners": f"{returns[learners].mean():.3f} (n={learners.sum()})"}
    if (~learners).any():
        out["mean return, scripted robots"] = f"{returns[~learners].mean():.3f} (n={(~learners).sum()})"
    return out


def gs_item_ages(env, agent: str) -> np.ndarray:
    """The ages of the 12 items of ``agent``'s region in the GS ``env`` (0: no item)."""
    return env.get_region_state(agent)[1]


def ls_item_ages(ls) -> np.ndarray:
    """The ages of the 12 items of a single-copy local simulator (0: no item)."""
    return ls.get_state()[1][0]


STUDY = StudySettings(budget=2_000_000, ppo_steps_per_second={"gs": 4900.0, "ials": 6300.0},
                     memory_variant={"item_lifetime": 8}, lifetime_probes=(gs_item_ages, ls_item_ages),
                     multi_agent_budget=204_800,
                     # the DIALS study, 256k steps x 36 robots: IPPO 297 s, DIALS 239-331 s
                     multi_agent_steps_per_second={"gs": 31_000.0, "ials": 32_000.0})
# SPEC §6: the warehouse AIP is a GRU (hidden 64, lr 1e-3) trained once, at the start, and
# rollouts are 8 steps (16 copies x 8 = 128 samples per update). 10 epochs of 8-episode
# minibatches: mean test cross-entropy 0.486 in 34 s for all 36 AIPs (20 epochs: 0.470 in
# 70 s; 40 epochs of 16: 0.476; untrained 1.09), measured on 10,000 steps.
# frame stack 1 for the multi-agent policies: the ablation's largest warehouse gain (4.4 ->
# 6.2 at 51,200 steps per agent; 296 inputs are mostly repeats), and the nearest-item rule on
# one observation scores 0.86 of the scripted robots (ials_zoo/warehouse/rules.py)
# DIALS's AIPs read their own last draw (autoregressive, lr 1e-2): a neighbour that lingers
# stays one arrival (docs/fidelity.md), and DIALS scored 13.3 against 12.4 with memoryless
# AIPs (10 and 5 seeds, 256,000 steps per agent; leaderboard/writeup.md)
# A single learner among scripted robots (robot_20, 512k steps, 3 seeds) reached 13.8 with
# 2,048 samples per update in minibatches of 256, against 8.9 with 512 in 128s; 4,096 in 512s
# and 2,048 in 128s scored 11.9 (docs/ablation.md, "What holds robot_20 back")
# The fidelity report's AIPs: lr 6e-3 decayed linearly to zero over 120 epochs (the mean rate of a
# constant 3e-3). Decayed from 3e-3 they learn too slowly that a parked neighbour never leaves
# (robot_20: 1.3 arrivals against 1.0 under all of 3 trainings); from 6e-3 all 51 rows of the
# report hold (docs/fidelity.md)
DIALS = DIALSSettings(aip_arch="gru", aip_hidden=64, aip_lr=1e-3, aip_epochs=10, aip_batch=8, copies=16,
                     collect_steps=10_000, refresh=0, frame_stack=1, aip_autoregressive=True,
                     ppo_samples_per_update=2048, ppo_batch_size=256, fidelity_aip_lr=6e-3,
                     fidelity_aip_epochs=120)

DOMAIN = Domain(
    env_id=R.DOMAIN_ID,
    description="36 robots collect items from the shelves of a warehouse floor (numpy)",
    parallel_env=parallel_env,
    local_simulator=local_simulator,
    region_spec=R.region_spec,
    possible_agents=R.possible_agents,
    observation_space=spaces.Box(0.0, 1.0, (R.OBS_SIZE,), np.float32),
    action_space=spaces.Discrete(4),
    default_agents=("robot_20",),
    default_predictor="gru",
    episode_length=R.DEFAULT_MAX_CYCLES,
    frame_stack=8,
    agent_options=("robots",),
    gs_options=("item_probability", "max_cycles", "item_lifetime", "robots"),
    null_influence=R.NONE,
    untrained_probs=((0.25, 0.25, 0.25, 0.25),) * R.N_SOURCES,
    metrics={"items_per_robot": "higher", "age_at_collection": "lower", "items_waiting": "lower"},
    # Fed the GS's own actions and u_t from the same start, the LS differs only where items
    # appear at other times (its own draws); the exact replay, with the GS's draws, is
    # tests/test_warehouse_local.py.
    replay_agreement=0.85,
    extras={
        "study": STUDY,
        "dials": DIALS,
        "viewer": ViewerSettings(legend=render.LEGEND, episode_summary=episode_summary),
        "bench": BenchSettings(scaling=("robots", ((4, 4), (6, 6), (10, 10)))),
    },
)
