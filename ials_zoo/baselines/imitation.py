"""A warm start from one of the domain's rules (``--imitate greedy``).

Before reinforcement learning begins, the rule drives a GS for ``--imitate-episodes`` episodes
while every agent's own observation is recorded, as the learner reads it (zero-padded to the
widest agent). The actors are then fitted to the rule's choices by cross-entropy
(:meth:`ials_zoo.learners.batched_ppo.BatchedPPO.imitate`). The learner starts where the rule
is, and PPO has to improve on it: the curve's first point scores the fitted actors. The
critics are fitted to the rule's discounted returns too, in the units PPO's critic learns (the
learner's reward scale, which keeps the demonstrations' statistics): an untrained critic's
first advantages are noise that PPO's first updates would write into the fitted actors. The
demonstrations and the fit count as training time.

Why: on RESCO's maps a learner that reads greedy's own count (``sumo_net_v0``'s ``wave``
observation) lands near greedy after its 100 episodes, and on the jammed maps far above it;
starting from greedy's choices asks PPO only for what greedy misses.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ials_zoo.core.spaces import stack_observations
from ials_zoo.core.streams import derived_seed
from ials_zoo.errors import BadInput
from ials_zoo.learners.batched_ppo import gae

DEFAULT_EPISODES = 2
MAX_EPISODES = 100  # RESCO's whole budget per light: more is a typo, not a warm start
# minibatch updates of the fit: on cologne8 (wave, 2 episodes, minibatches of 128) 180 fit 81% of
# greedy's choices and 600 fit 99.9%
UPDATES = 600
# the fit's own rate, whatever PPO's (a run that fine-tunes slowly still fits the rule whole)
LEARNING_RATE = 1e-3


@dataclass(frozen=True)
class Imitation:
    """What ``--imitate`` asks of a run: the domain's rule ``name`` and its GS episodes."""

    domain: object
    name: str
    rule: object
    episodes: int = DEFAULT_EPISODES


def imitation_of(domain, name: str | None, episodes: int | None, frame_stack: int, recurrent_hidden: int):
    """The :class:`Imitation` that ``--imitate`` asks for, or None; clear errors naming the flag
    for a rule the domain lacks, one whose choices cannot be read (the GS's own controller drives
    it), a count out of range, and a learner that reads more than one observation."""
    if name is None:
        if episodes is not None:
            raise BadInput("--imitate-episodes needs --imitate RULE")
        return None
    rules = domain.rules
    if name not in rules:
        raise BadInput(f"--imitate: {domain.env_id} has no rule {name!r}; its rules: {', '.join(rules) or 'none'}")
    if rules[name].make is None:
        raise BadInput(f"--imitate {name}: under that rule the GS's own controller drives the agents, so its "
                       "choices cannot be read; imitate a rule that chooses (e.g. greedy)")
    if episodes is not None and not 1 <= episodes <= MAX_EPISODES:
        raise BadInput(f"--imitate-episodes must be in 1..{MAX_EPISODES}, got {episodes}")
    if frame_stack > 1 or recurrent_hidden:
        raise BadInput("--imitate fits actors that read one observation: leave --frame-stack 1 and "
                       "--recurrent-hidden 0")
    return Imitation(domain, name, rules[name], DEFAULT_EPISODES if episodes is None else int(episodes))


def rule_demonstrations(domain, rule, agents: list, options: dict, episodes: int, seed: int, width: int):
    """``(obs [A, N, width], actions [A, N], rewards [A, N], ends [N])``: every decision of
    ``episodes`` GS episodes (seeds derived from ``seed``) with ``rule`` choosing for every
    agent; ``ends[t]``: an episode ended after decision ``t``."""
    env = domain.parallel_env(learners=agents, **options, **rule.env_options)
    observed, chosen, rewards, ends = [], [], [], []
    try:
        controller = rule.make(env)
        for k in range(episodes):
            obs, _ = env.reset(seed=derived_seed(seed, "imitation", k))
            while env.agents:
                actions = controller(env)
                observed.append(stack_observations(obs, agents, width))
                chosen.append([actions[a] for a in agents])
                obs, reward, *_ = env.step(actions)
                rewards.append([reward[a] for a in agents])
                ends.append(not env.agents)
    finally:
        env.close()
    return np.stack(observed, axis=1), np.asarray(chosen, np.int64).T, np.asarray(rewards, float).T, np.asarray(ends)


def scaled_returns(learner, rewards: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """``[A, N]``: the discounted return from each decision of the demonstrations, in the units
    PPO's critic learns: each reward over the running deviation of the discounted return, with
    the learner's own reward scale (:class:`~ials_zoo.learners.batched_ppo.RewardScale`), which
    keeps these statistics so that its first rollouts are scaled as the demonstrations were."""
    cfg, scale = learner.cfg, learner.reward_scale
    scaled = rewards.copy()
    if cfg.normalize_reward:
        running = scale.returns
        scale.returns = np.zeros((rewards.shape[0], 1))
        for t in range(rewards.shape[1]):
            scaled[:, t] = scale(rewards[:, t:t + 1], bool(ends[t]))[:, 0]
        scale.returns = np.zeros_like(running)
    # returns to go: GAE with lambda 1 over a critic of zeros ([T, A, 1], as the rollouts' arrays)
    zeros = np.zeros((scaled.shape[1], scaled.shape[0], 1))
    _, returns = gae(scaled.T[:, :, None], zeros, np.asarray(ends, float), zeros[0], cfg.gamma, 1.0)
    return returns[:, :, 0].T


def warm_start(learner, imitation: Imitation, agents: list, options: dict, seed: int, width: int) -> dict:
    """Fit ``learner``'s actors (a :class:`BatchedPPO`) to the rule over its demonstrations;
    returns what the run records of it (the rule, episodes, decisions, fit and seconds)."""
    rule_name, episodes = imitation.name, imitation.episodes
    started = time.perf_counter()
    print(f"imitating {rule_name}: {episodes} GS episode{'s' if episodes > 1 else ''} of its choices, then "
         f"{UPDATES} updates of cross-entropy ...", flush=True)
    obs, actions, rewards, ends = rule_demonstrations(imitation.domain, imitation.rule, agents, options, episodes,
                                                      seed, width)
    fit = learner.imitate(obs, actions, UPDATES, derived_seed(seed, "imitation-fit"),
                          returns=scaled_returns(learner, rewards, ends), learning_rate=LEARNING_RATE)
    record = {"rule": rule_name, "episodes": episodes, "decisions": int(actions.shape[1]), "updates": UPDATES,
              "loss": round(fit["loss"], 6), "value_loss": round(fit["value_loss"], 6),
              "agreement": round(fit["agreement"], 6),
              "seconds": round(time.perf_counter() - started, 3)}
    print(f"imitated {rule_name}: the actors now choose as it does at {fit['agreement']:.1%} of its "
         f"{actions.size:,} choices ({record['seconds']:.0f} s)", flush=True)
    return record


__all__ = ["DEFAULT_EPISODES", "LEARNING_RATE", "UPDATES", "Imitation", "MAX_EPISODES", "imitation_of", "rule_demonstrations",
           "scaled_returns", "warm_start"]
