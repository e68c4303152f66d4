"""Random numbers per (agent, copy): a batch of regions draws exactly what each region alone
would draw.

A batched local simulator (or the AIPs of several agents) takes its randomness from
:class:`CopyStreams`: one generator per row, seeded from the run's seed, the agent's *name*
and the copy's index, read in blocks of :data:`BLOCK` steps (one generator call per row every
``BLOCK`` steps, not one per step). So a row's numbers do not depend on which other agents
share the batch, how many copies there are of them, or which process holds it: agent
``a``'s copy ``j`` in a batch of all agents draws what a single-agent simulator of ``a`` would
(the multi-agent IALS equals the single-agent IALS given the same seed and influence sources,
and DIALS's simulators draw the same with any number of workers).
"""

from __future__ import annotations

import zlib

import numpy as np

BLOCK = 64


def agent_key(agent: str) -> int:
    """A stable 32-bit number for an agent's name (the same in every process and run)."""
    return zlib.crc32(agent.encode())


def row_seed_sequences(seed: int | None, agents, n_envs: int, salt: int = 0) -> list[np.random.SeedSequence]:
    """One ``SeedSequence`` per row (agent-major), from ``seed`` (None: fresh entropy),
    each agent's name, the copy index and ``salt`` (to separate uses of one seed)."""
    root = np.random.SeedSequence(seed)
    return [np.random.SeedSequence(root.entropy, spawn_key=(int(salt), agent_key(a), j))
            for a in agents for j in range(n_envs)]


class CopyStreams:
    """Uniform numbers in ``[0, 1)``, ``width`` per row and step, one independent stream per
    row (see the module docstring)."""

    def __init__(self, agents, n_envs: int, width: int, salt: int = 0):
        self.agents, self.n_envs, self.width, self.salt = tuple(agents), int(n_envs), int(width), int(salt)
        self.rows = len(self.agents) * self.n_envs
        self.seed(None)

    def seed(self, seed: int | None) -> None:
        self._gens = [np.random.default_rng(s) for s in row_seed_sequences(seed, self.agents, self.n_envs, self.salt)]
        self._buf = None
        self._t = BLOCK

    def next(self) -> np.ndarray:
        """The next step's numbers, ``[rows, width]`` (a view: read it before the next call)."""
        if self._t == BLOCK:
            self._buf = np.stack([g.random((BLOCK, self.width)) for g in self._gens], axis=1)
            self._t = 0
        row = self._buf[self._t]
        self._t += 1
        return row

    def generator(self, row: int = 0) -> np.random.Generator:
        """The generator of one row (for a single-row fast path that reads blocks itself)."""
        return self._gens[row]


def derived_seed(seed: int, use: str, *counters: int) -> int:
    """A 32-bit seed for one ``use`` of a run's ``seed`` (``"episode"``, ``"update"``) at
    ``counters`` (the episode's index, the update's): counter-based, so a resumed run
    recomputes it from the counters it saved instead of saving a generator's state. In
    ``[0, 2**31 - 2]``, which SUMO accepts too."""
    state = np.random.SeedSequence([int(seed), agent_key(use), *(int(k) for k in counters)]).generate_state(1)[0]
    return int(state) % (2**31 - 1)


__all__ = ["BLOCK", "CopyStreams", "agent_key", "derived_seed", "row_seed_sequences"]
