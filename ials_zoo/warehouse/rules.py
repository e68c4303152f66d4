"""Observation-only rules for the warehouse robots: yardsticks for the learners.

Each reads only what a robot's policy reads, its 37-bit observations, and steps along a
shortest path to an item of its region:

* :func:`nearest_item`: the nearest item (ties in the item-bit order); up when the region is
  empty, which leaves the robot on the top shelf line, far from most items.
* :func:`nearest_item_centred`: the same, but back to the region's centre when the region is
  empty, where the next item is on average closest.
* :class:`OldestSeenItem`: remembers, over the whole episode, the step at which each item bit
  turned on and steps towards the item seen longest (ties: the nearest); back to the centre
  when the region is empty. It knows nothing the observations do not show, so it is what a
  policy with episode-long memory can reach.

The scripted robots go to the *oldest* item (they read the items' ages) and make a random move
when their region is empty. On ``robot_20`` among scripted robots the first rule scores well
below them, but the second is within the noise of them without any memory: a memoryless
policy can reach the scripted robot's score, and where idle time is spent matters more than
the items' ages (numbers in ``docs/ablation.md``).

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


def _newest(observation) -> tuple[int, np.ndarray]:
    """``(local position, item bits)`` of the newest 37 entries (a stacked observation works)."""
    obs = np.asarray(observation).reshape(-1)[-R.OBS_SIZE:]
    return int(np.argmax(obs[:R.N_CELLS])), obs[R.N_CELLS:] > 0


def toward_centre(position: int) -> int:
    """A move towards the region's centre, rows first (up at the centre itself: a robot
    cannot stand still, and it comes back on the next step)."""
    row, col = divmod(position, R.SIZE)
    centre_row, centre_col = divmod(R.CENTRE, R.SIZE)
    if row != centre_row:
        return 1 if row < centre_row else 0
    if col != centre_col:
        return 3 if col < centre_col else 2
    return 0


def _to_nearest(position: int, items: np.ndarray) -> int:
    nearest = items[np.argmin(R.DIST[position, R.ITEM_POS[items]])]
    return int(R.NEXT_MOVE[position, nearest])


def nearest_item(observation) -> int:
    """The memoryless rule's action for one robot's observation; up when no item is in sight."""
    position, present = _newest(observation)
    items = np.flatnonzero(present)
    return 0 if len(items) == 0 else _to_nearest(position, items)


def nearest_item_centred(observation) -> int:
    """:func:`nearest_item`, but back to the centre when no item is in sight."""
    position, present = _newest(observation)
    items = np.flatnonzero(present)
    return toward_centre(position) if len(items) == 0 else _to_nearest(position, items)


class OldestSeenItem:
    """The rule with episode memory: ``rule(observation) -> action``, one instance per robot,
    :meth:`reset` at every episode start (:func:`ials_zoo.evaluation.evaluate` calls it).

    An item that vanished and reappeared between two observations (taken and replaced in one
    step) keeps its first sighting; that is the only age it gets wrong.
    """

    frame_stack = 1

    def __init__(self):
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        self._first_seen = np.full(len(R.ITEM_POS), -1, dtype=np.int64)
        self._step = 0

    def __call__(self, observation) -> int:
        position, present = _newest(observation)
        self._first_seen[present & (self._first_seen < 0)] = self._step
        self._first_seen[~present] = -1
        self._step += 1
        items = np.flatnonzero(present)
        if len(items) == 0:
            return toward_centre(position)
        return _to_nearest(position, items[self._first_seen[items] == self._first_seen[items].min()])


def score_joint(episodes: int = 20, rule=nearest_item, **options) -> tuple[float, float, float]:
    """``(mean, low, high)`` over the protocol's episodes of the mean return per robot when
    every robot follows ``rule`` (``None``: every robot scripted). A class (like
    :class:`OldestSeenItem`) gets one fresh instance per robot and episode."""
    env = parallel_env(scripted_learners=rule is None, **options)
    scores = []
    try:
        for seed in eval_seeds(episodes):
            obs, _ = env.reset(seed=seed)
            totals = dict.fromkeys(env.agents, 0.0)
            rules = {a: (rule() if isinstance(rule, type) else rule) for a in env.agents}
            while env.agents:
                actions = {a: (0 if rule is None else rules[a](obs[a])) for a in env.agents}
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
    rules = (("nearest-item rule", nearest_item), ("nearest-item rule, centred", nearest_item_centred),
             ("oldest-seen-item rule (episode memory)", OldestSeenItem), ("scripted", None))
    for name, rule in rules:
        policy = "scripted" if rule is None else (rule() if isinstance(rule, type) else rule)
        ev = evaluate("warehouse_v0", args.agent, policy, episodes=args.episodes)
        print(f"{args.agent} among scripted robots, {name}: {ev.mean:.2f} [{ev.ci_low:.2f}, {ev.ci_high:.2f}]")
    for name, rule in rules:
        mean, low, high = score_joint(args.episodes, rule)
        print(f"every robot, {name}: {mean:.2f} [{low:.2f}, {high:.2f}] per robot")


if __name__ == "__main__":
    main()
