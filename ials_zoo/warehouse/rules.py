"""A memoryless rule for the warehouse robots: a yardstick for the learners.

:func:`nearest_item` reads only a robot's 37-bit observation and steps along a shortest path
to the nearest item of its region (ties in the item-bit order; up when the region is empty).
The scripted robots go to the *oldest* item, which no single observation shows: the gap
between the two is what memory of the items' ages is worth. A learner that reads one
observation can be expected to reach the rule, not the scripted robots.

``python -m ials_zoo.warehouse.rules [--episodes 20]`` scores it on the protocol's seeds
(:func:`ials_zoo.evaluation.eval_seeds`), beside the scripted robots: one robot (default
``robot_20``) following it among scripted neighbours (the single-agent track), and every
robot following it (the multi-agent track; the score is the mean over robots of each robot's
return, as for a joint policy).
"""

from __future__ import annotations

import argparse

import numpy as np

from ials_zoo.evaluation import eval_seeds, evaluate
from ials_zoo.stats import t_interval
from ials_zoo.warehouse import regions as R
from ials_zoo.warehouse.env import parallel_env


def nearest_item(observation) -> int:
    """The rule's action for one robot's observation (the newest 37 entries are read, so a
    stacked observation works too)."""
    obs = np.asarray(observation).reshape(-1)[-R.OBS_SIZE:]
    position = int(np.argmax(obs[:R.N_CELLS]))
    items = np.flatnonzero(obs[R.N_CELLS:])
    if len(items) == 0:
        return 0
    nearest = items[np.argmin(R.DIST[position, R.ITEM_POS[items]])]
    return int(R.NEXT_MOVE[position, nearest])


def score_joint(episodes: int = 20, rule=nearest_item, **options) -> tuple[float, float, float]:
    """``(mean, low, high)`` over the protocol's episodes of the mean return per robot when
    every robot follows ``rule`` (``None``: every robot scripted)."""
    env = parallel_env(scripted_learners=rule is None, **options)
    scores = []
    try:
        for seed in eval_seeds(episodes):
            obs, _ = env.reset(seed=seed)
            totals = dict.fromkeys(env.agents, 0.0)
            while env.agents:
                actions = {a: (0 if rule is None else rule(obs[a])) for a in env.agents}
                obs, rewards, _, _, _ = env.step(actions)
                for a, r in rewards.items():
                    totals[a] += r
            scores.append(float(np.mean(list(totals.values()))))
    finally:
        env.close()
    return t_interval(scores)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agent", default="robot_20", help="the robot of the single-agent score")
    parser.add_argument("--episodes", type=int, default=20)
    args = parser.parse_args(argv)
    for name, policy in (("nearest-item rule", nearest_item), ("scripted", "scripted")):
        ev = evaluate("warehouse_v0", args.agent, policy, episodes=args.episodes)
        print(f"{args.agent} among scripted robots, {name}: {ev.mean:.2f} [{ev.ci_low:.2f}, {ev.ci_high:.2f}]")
    for name, rule in (("nearest-item rule", nearest_item), ("scripted", None)):
        mean, low, high = score_joint(args.episodes, rule)
        print(f"every robot, {name}: {mean:.2f} [{low:.2f}, {high:.2f}] per robot")


if __name__ == "__main__":
    main()
