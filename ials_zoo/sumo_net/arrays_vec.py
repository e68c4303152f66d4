"""Copies of a network's multi-agent IALS on arrays, stepped as one batch: what DIALS steps
(:class:`ials_zoo.learners.gs_vec.GSVecEnv` with ``simulator="ials"``, ``local="arrays"``).

One :class:`~ials_zoo.sumo_net.arrays_core.ArrayNetCore` holds every light's region of every copy;
each decision every light's AIP samples its sources for all copies at once (its d-sets stacked),
and RESCO's observations and rewards come from the measures in one numpy pass. The agents,
spaces, observations and rewards are :class:`~ials_zoo.sumo_net.ials_env.IALSNetEnv`'s (RESCO's
``drq_norm`` and ``wait_norm`` by default); the lights that do not learn run their own program.
"""

from __future__ import annotations

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.sumo_net.arrays_core import ArrayNetCore
from ials_zoo.sumo_net.ials_env import resolve_predictors
from ials_zoo.sumo_net.island import entry_tables
from ials_zoo.sumo_net.mdp import BATCHED_OBSERVATIONS, N_FEATURES, lanes_tables, observation_fn, reward_fn, wait_norm
from ials_zoo.sumo_net.names import SCENARIO_OPTIONS
from ials_zoo.sumo_net.network import read_network
from ials_zoo.sumo_net.scenario import scenario_of
from ials_zoo.utils import check_seed

KNOWN = ("record_seconds", "record_seed", "observation", "reward", "max_distance", "local", "learners", "backend",
         "fresh_process", "region_data", "render_mode", *SCENARIO_OPTIONS)


class ArrayIALSCopies:
    """``len(seeds)`` copies of every light's IALS on arrays (module docstring), with
    :class:`~ials_zoo.learners.gs_vec.GSVecEnv`'s copies' contract: ``reset(seeds)`` and
    ``step(actions [A, copies])`` give observations ``[A, copies, width]`` (zero-padded to the
    widest light's), rewards ``[A, copies]`` and whether the episode ended."""

    def __init__(self, agents, predictor, seeds, record_seconds: int | None = None, record_seed: int = 0,
                 observation: str = "drq_norm", reward: str = "wait_norm", max_distance: float = 200.0, **options):
        unknown = sorted(set(options) - set(KNOWN))
        if unknown:
            raise BadInput(f"unknown option(s) of the IALS on arrays: {unknown}")
        given = {k: v for k, v in options.items() if k in SCENARIO_OPTIONS}
        self.scenario = s = scenario_of(**given)
        lights = list(read_network(s.net_file).lights)
        ids = [x.id for x in lights]
        self.agents = list(agents or ids)
        missing = [a for a in self.agents if a not in ids]
        if missing:
            raise BadInput(f"unknown agent(s) {missing[:3]}: not traffic lights of {s.name}")
        self._observe, self._reward = observation_fn(observation), reward_fn(reward)
        self._given = given
        self.predictors = resolve_predictors(predictor, ids, given)
        tables = entry_tables(s, ids, record_seconds, record_seed)
        self.copies, self.ids = len(seeds), ids
        self.core = ArrayNetCore(s.net_file, s.route_files, s.begin, s.decision_seconds, s.yellow_seconds, ids,
                                 [x.lanes for x in lights], [tables[x] for x in ids], controlled=self.agents,
                                 copies=self.copies, max_distance=max_distance)
        self.core.as_blocks = True
        counts = [len(x.lanes) for x in lights]
        self.lane_start = np.concatenate([[0], np.cumsum(counts)])  # every light's rows in a copy's measures
        self.width = N_FEATURES * max(counts[ids.index(a)] for a in self.agents)
        self.agent_rows = [ids.index(a) for a in self.agents]
        self.action_counts = [lights[r].n_actions for r in self.agent_rows]
        self.seeds = list(seeds)
        self._rng = np.random.default_rng(self.seeds[0])
        self.decisions, self.decision = s.decisions, 0

    def reset(self, seeds=None):
        """A new episode of every copy; ``seeds`` (one per copy) seed it, else the copies'
        own stream continues."""
        if seeds is not None:
            self.seeds = [check_seed(x) for x in seeds]
            if len(self.seeds) != self.copies:
                raise BadInput(f"reset: {len(self.seeds)} seeds for {self.copies} copies")
        if self.seeds[0] is not None:
            self._rng = np.random.default_rng(np.random.SeedSequence([int(x) for x in self.seeds]))
        self.seeds = [None] * self.copies
        seed = int(self._rng.integers(2**31 - 1))
        for p in self.predictors.values():
            p.reset(self.copies)
        self.decision = 0
        return self._outputs(self.core.reset(seed))[0]

    def step(self, actions):
        actions = np.asarray(actions)
        if actions.shape != (len(self.agents), self.copies):
            raise BadInput(f"actions must have shape ({len(self.agents)}, {self.copies}), got {actions.shape}")
        blocks = [self.predictors[x].sample(d, self._rng) for x, d in zip(self.ids, self.core.dset_blocks())]
        obs, rewards = self._outputs(self.core.step_blocks(actions.T.reshape(-1).tolist(), blocks))
        self.decision += 1
        return obs, rewards, self.decision >= self.decisions

    def _outputs(self, result):
        """Every learner's observation and reward in every copy, one light's copies at a time."""
        measures, phases, _time = result
        blocks = measures.reshape(self.copies, -1, measures.shape[1])
        phases = phases.reshape(self.copies, -1)
        obs = np.zeros((len(self.agents), self.copies, self.width), np.float32)
        rewards = np.zeros((len(self.agents), self.copies))
        for i, r in enumerate(self.agent_rows):
            block = blocks[:, self.lane_start[r]:self.lane_start[r + 1]]  # [copies, its lanes, 5]
            lanes = block.shape[1]
            if self._observe in BATCHED_OBSERVATIONS:
                table = lanes_tables(block.reshape(-1, block.shape[2]), phases[:, r], np.arange(self.copies + 1) * lanes,
                                     BATCHED_OBSERVATIONS[self._observe])
                obs[i, :, :lanes * N_FEATURES] = table.reshape(self.copies, -1)
            else:
                obs[i, :, :lanes * N_FEATURES] = [self._observe(b, int(p)) for b, p in zip(block, phases[:, r])]
            if self._reward is wait_norm:
                rewards[i] = np.clip(-block[:, :, 1].sum(axis=1) / 224.0, -4.0, 4.0)
            else:
                rewards[i] = [self._reward(b, int(p)) for b, p in zip(block, phases[:, r])]
        return obs, rewards

    def set_predictors(self, predictors) -> None:
        """New AIPs (an AIP set file, one spec or ``{light: ...}``), from the next decision on."""
        self.predictors = resolve_predictors(predictors, self.ids, self._given)
        for p in self.predictors.values():
            p.reset(self.copies)

    def close(self) -> None:
        self.core.close()


__all__ = ["ArrayIALSCopies"]
