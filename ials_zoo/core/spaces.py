"""Joint arrays over agents whose spaces may differ (e.g. the junctions of a real network).

Multi-agent learners stack the agents' observations into ``[A, width]``; where agents have
observations of different lengths, each is zero-padded to the longest, and where they have
different action counts, a learner masks the actions an agent lacks (``action_counts``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ials_zoo.errors import BadInput


@dataclass(frozen=True)
class JointSizes:
    """``obs_size``: the stacked width (the longest observation); ``n_actions``: the most
    actions; ``action_counts``: each agent's own count, or None when all agents share one."""

    obs_size: int
    n_actions: int
    action_counts: tuple | None = None


def sizes_of_env(env, agents) -> JointSizes:
    """The joint sizes of ``agents`` in a live GS ``env`` (flat ``Box`` / ``Discrete`` spaces)."""
    widths, counts = [], []
    for a in agents:
        obs, act = env.observation_space(a), env.action_space(a)
        if len(obs.shape) != 1 or not hasattr(act, "n"):
            raise BadInput(f"agent {a!r}: joint learners need a flat Box observation and Discrete actions")
        widths.append(int(obs.shape[0]))
        counts.append(int(act.n))
    same = len(set(counts)) == 1
    return JointSizes(max(widths), max(counts), None if same else tuple(counts))


def joint_sizes(domain, agents, options: dict) -> JointSizes:
    """The joint sizes of ``agents``: the domain's shared spaces, or (agents with their own)
    read from a GS built for it (no simulation is started)."""
    if domain.observation_space is not None and domain.action_space is not None:
        return JointSizes(int(np.prod(domain.observation_space.shape)), int(domain.action_space.n))
    env = domain.parallel_env(learners=list(agents), **options)
    try:
        return sizes_of_env(env, agents)
    finally:
        env.close()


def stack_observations(obs: dict, agents, width: int | None = None) -> np.ndarray:
    """``[A, width]``: each agent's observation, zero-padded to ``width`` (default: as they are)."""
    rows = [np.asarray(obs[a]) for a in agents]
    if width is None or all(r.shape[-1] == width for r in rows):
        return np.stack(rows)
    out = np.zeros((len(rows), width), np.result_type(*rows))
    for i, r in enumerate(rows):
        if r.shape[-1] > width:
            raise BadInput(f"agent {agents[i]!r}: an observation of {r.shape[-1]} is wider than {width}")
        out[i, :r.shape[-1]] = r
    return out


__all__ = ["JointSizes", "joint_sizes", "sizes_of_env", "stack_observations"]
