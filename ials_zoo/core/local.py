"""The local-simulator interface every domain implements (paper §4, Algorithm 2).

A local simulator (LS) simulates agents' regions alone. It cannot know what the rest of the
system does, so each step it is *given* the influence sources ``u_t`` (sampled by an influence
predictor) together with the agents' actions.

The interface is batched: one ``LocalSimulator`` holds ``n_envs`` independent copies of the
region of each of its ``agents`` -- ``n_copies = len(agents) * n_envs`` rows, agent-major
(rows ``i * n_envs .. (i + 1) * n_envs - 1`` are agent ``agents[i]``'s copies) -- and advances
them in lock-step, so that one influence-predictor call serves all of them. One agent with
``n_envs=1`` is the plain single-env case; every agent of a GS in one LS is the multi-agent
IALS (DIALS). The regions of a domain share one layout (the same influence sources and d-set
size; a region with fewer neighbours sees the missing ones as always "no influence"), so the
rows stack. All episodes of the zoo end by truncation after a fixed number of steps, so the
copies always reset together.

A local simulator may offer a *single-copy fast path* (:attr:`LocalSimulator.supports_step_single`):
with exactly one copy, :meth:`~LocalSimulator.step_single` takes plain Python ints and
:meth:`~LocalSimulator.observe_single` returns shared read-only views, which the single-agent
IALS uses to skip per-step array construction.
"""

from __future__ import annotations

import abc

import numpy as np
from gymnasium import spaces

from ials_zoo.core.region import RegionSpec
from ials_zoo.errors import BadInput, BadInputType


def agent_list(agents) -> tuple[str, ...]:
    """``agents`` (one id, or a sequence of distinct ids) as a non-empty tuple."""
    if isinstance(agents, str):
        return (agents,)
    out = tuple(agents)
    if not out:
        raise BadInput("a local simulator needs at least one agent")
    if len(set(out)) != len(out):
        raise BadInput(f"agents repeat: {list(out)}")
    return out


def check_n_envs(n_envs) -> int:
    if isinstance(n_envs, bool) or not isinstance(n_envs, (int, np.integer)):
        raise BadInputType(f"n_envs must be a positive int, got {n_envs!r}")
    if n_envs < 1:
        raise BadInput(f"n_envs must be a positive int, got {n_envs!r}")
    return int(n_envs)


class LocalSimulator(abc.ABC):
    """``n_envs`` copies of the region of each of ``agents``, stepped together.

    Attributes:
        agents: the agents whose regions are simulated (distinct).
        regions: their layouts, one per agent (each the GS's ``region_spec(agent)``).
        observation_space: one agent's observation space, identical to the GS's.
        action_space: one agent's action space, identical to the GS's.
        n_envs: copies per agent.
        max_cycles: episode length; the caller truncates after this many steps.
    """

    agents: tuple[str, ...]
    regions: tuple[RegionSpec, ...]
    observation_space: spaces.Space
    action_space: spaces.Space
    n_envs: int
    max_cycles: int

    supports_step_single: bool = False
    """Whether :meth:`step_single` / :meth:`observe_single` may be used (one copy in all)."""

    @property
    def n_copies(self) -> int:
        """Rows of every batch: ``len(agents) * n_envs``."""
        return len(self.agents) * self.n_envs

    @property
    def region(self) -> RegionSpec:
        """The region of a single-agent local simulator."""
        if len(self.regions) != 1:
            raise AttributeError(
                f"this local simulator holds {len(self.regions)} agents' regions; use .regions"
            )
        return self.regions[0]

    def copy_agents(self) -> list[str]:
        """The agent of each row, in row order."""
        return [a for a in self.agents for _ in range(self.n_envs)]

    @abc.abstractmethod
    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Start a new episode in every copy.

        Returns:
            ``(obs, dsets)``: ``obs`` of shape ``(n_copies, *observation_space.shape)`` and,
            for each d-set kind, an array of shape ``(n_copies, dset_size(kind))`` (uint8).
        """

    @abc.abstractmethod
    def step(
        self, actions: np.ndarray, influences: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Advance every copy by one step.

        Args:
            actions: shape ``(n_copies,)``, one action per copy.
            influences: int array of shape ``(n_copies, n_sources)``; ``u_t`` per copy.

        Returns:
            ``(obs, rewards, dsets)`` for the new state; rewards has shape ``(n_copies,)``.
        """

    def step_single(self, action: int, *influence: int) -> float:
        """The single copy's step from Python ints (no checks); returns the reward. The new
        state's observation and d-sets come from :meth:`observe_single`."""
        raise NotImplementedError(f"{type(self).__name__} has no single-copy fast path")

    def observe_single(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """``(obs, {kind: (1, D)})`` of the single copy: shared read-only arrays."""
        raise NotImplementedError(f"{type(self).__name__} has no single-copy fast path")

    def close(self) -> None:
        """Release resources (a SUMO simulation, a worker process)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
