"""The local-simulator interface every domain implements (paper §4, Algorithm 2).

A local simulator (LS) simulates one agent's region alone. It cannot know what the rest of the
system does, so each step it is *given* the influence sources ``u_t`` (sampled by an influence
predictor) together with the agent's action.

The interface is batched: one ``LocalSimulator`` holds ``n_envs`` independent copies of the
region and advances them in lock-step, so that the influence predictor can be called once per
step for all of them. ``n_envs=1`` is the plain single-env case. All episodes of the zoo end by
truncation after a fixed number of steps, so the copies always reset together.
"""

from __future__ import annotations

import abc

import numpy as np
from gymnasium import spaces

from ials_zoo.core.region import RegionSpec


class LocalSimulator(abc.ABC):
    """``n_envs`` copies of one agent's region, stepped together.

    Attributes:
        region: the region's layout (same as the GS's ``region_spec(agent)``).
        observation_space: the agent's observation space, identical to the GS's.
        action_space: the agent's action space, identical to the GS's.
        n_envs: number of copies.
        max_cycles: episode length; the caller truncates after this many steps.
    """

    region: RegionSpec
    observation_space: spaces.Space
    action_space: spaces.Space
    n_envs: int
    max_cycles: int

    @abc.abstractmethod
    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Start a new episode in every copy.

        Returns:
            ``(obs, dsets)``: ``obs`` of shape ``(n_envs, *observation_space.shape)`` and, for
            each d-set kind, an array of shape ``(n_envs, region.dset_size(kind))`` (uint8).
        """

    @abc.abstractmethod
    def step(
        self, actions: np.ndarray, influences: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Advance every copy by one step.

        Args:
            actions: shape ``(n_envs,)``, one action per copy.
            influences: int array of shape ``(n_envs, region.n_sources)``; ``u_t`` per copy.

        Returns:
            ``(obs, rewards, dsets)`` for the new state; rewards has shape ``(n_envs,)``.
        """

    def close(self) -> None:
        """Release resources (a SUMO simulation, a worker process)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
