"""``relay_v0``: packets travel down a line of relay nodes (a toy domain for the contract test).

Nodes ``node_0 .. node_{n-1}`` sit on a line. Node 0 receives a new packet from outside with
probability ``arrival_probability`` per step; every node holds a queue of at most ``capacity``
packets. Action: ``Discrete(2)``: 0 = hold, 1 = forward one packet to the next node (the last
node's packets leave the system). A packet forwarded at step t is in the next queue after the
step (it is dropped when that queue is full). Scripted nodes forward whenever they hold a
packet. Observation: the one-hot of the node's queue length (``capacity + 1`` bits). Reward:
``-queue / capacity`` after the step. Episodes: ``max_cycles`` steps, then truncation.

Region of a node: its queue. Influence source: one bit, "a packet came from the left
neighbour" (always 0 at node 0, which has no left neighbour). D-set: the queue one-hot (both
kinds). The LS is one node alone: its left neighbour's packets are the influence; node 0's LS
draws its outside arrivals itself.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from ials_zoo.core.domains import Domain
from ials_zoo.core.extras import StudySettings
from ials_zoo.core.local import LocalSimulator, agent_list, check_n_envs
from ials_zoo.core.region import INFLUENCE_KEY, RegionSpec
from ials_zoo.core.streams import CopyStreams

ENV_ID = "relay_v0"


def possible_agents(nodes: int = 5, **_options) -> list[str]:
    if isinstance(nodes, bool) or not isinstance(nodes, int) or nodes < 2:
        raise ValueError(f"nodes must be an int >= 2, got {nodes!r}")
    return [f"node_{i}" for i in range(nodes)]


def _index(agent, nodes) -> int:
    agents = possible_agents(nodes)
    if agent not in agents:
        raise ValueError(f"unknown agent {agent!r}; relay_v0 has {agents[0]}..{agents[-1]}")
    return agents.index(agent)


def region_spec(agent, nodes: int = 5, capacity: int = 4, arrival_probability: float = 0.3, **_options) -> RegionSpec:
    _index(agent, nodes)
    bits = tuple(f"queue_{k}" for k in range(capacity + 1))
    return RegionSpec(domain=ENV_ID, agent=agent, influence_names=("from_left",), influence_classes=(2,),
                      dset_names={"dset": bits, "full": bits},
                      params={"nodes": nodes, "capacity": capacity, "arrival_probability": arrival_probability})


class RelayEnv(ParallelEnv):
    """The GS (see the module docstring)."""

    metadata = {"name": ENV_ID, "render_modes": ["ansi", "human", "rgb_array"], "is_parallelizable": True,
                "render_fps": 4}

    def __init__(self, learners=None, nodes=5, capacity=4, arrival_probability=0.3, max_cycles=50,
                 scripted_learners=False, render_mode=None):
        self.nodes, self.capacity, self.p, self.max_cycles = nodes, capacity, float(arrival_probability), max_cycles
        everyone = possible_agents(nodes)
        self.possible_agents = everyone if learners is None else [everyone[_index(a, nodes)] for a in learners]
        self._idx = np.array([everyone.index(a) for a in self.possible_agents])
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"unknown render_mode {render_mode!r}")
        self.render_mode, self.scripted = render_mode, bool(scripted_learners)
        obs = spaces.Box(0.0, 1.0, (capacity + 1,), np.float32)
        self.observation_spaces = dict.fromkeys(self.possible_agents, obs)
        self.action_spaces = dict.fromkeys(self.possible_agents, spaces.Discrete(2))
        self.state_space = spaces.Box(0.0, 1.0, (nodes,), np.float32)
        self.agents, self._rng, self._q, self._t = [], np.random.default_rng(), np.zeros(nodes, np.int64), 0

    def observation_space(self, agent):
        return self.observation_spaces[agent]

    def action_space(self, agent):
        return self.action_spaces[agent]

    def region_spec(self, agent):
        return region_spec(agent, self.nodes, self.capacity, self.p)

    def state(self):
        return (self._q / self.capacity).astype(np.float32)

    def _views(self, influence):
        onehot = np.eye(self.capacity + 1, dtype=np.uint8)[self._q[self._idx]]
        obs = {a: onehot[k].astype(np.float32) for k, a in enumerate(self.agents)}
        infos = {a: {INFLUENCE_KEY: np.array([influence[i]], np.int64), "dset": onehot[k].copy(),
                     "dset_full": onehot[k].copy()} for k, (a, i) in enumerate(zip(self.agents, self._idx))}
        return obs, infos

    def reset(self, seed=None, options=None):
        if seed is not None or self._t == 0:
            self._rng = np.random.default_rng(seed)
        self._q[:] = 0
        self._t = 0
        self.agents = list(self.possible_agents)
        return self._views(np.zeros(self.nodes, np.int64))

    def step(self, actions):
        forward = (self._q > 0).astype(np.int64)  # scripted: forward whenever holding a packet
        if not self.scripted:
            for k, a in enumerate(self.agents):
                forward[self._idx[k]] = int(actions[a]) if self._q[self._idx[k]] > 0 else 0
        arrival = self._rng.random() < self.p
        incoming = np.concatenate([[0], forward[:-1]])  # from the left neighbour
        self._q -= forward
        self._q[0] += arrival
        self._q = np.minimum(self._q + incoming, self.capacity)
        self._t += 1
        obs, infos = self._views(incoming)
        rewards = {a: float(-self._q[i] / self.capacity) for a, i in zip(self.agents, self._idx)}
        done = self._t >= self.max_cycles
        terms = dict.fromkeys(self.agents, False)
        truncs = dict.fromkeys(self.agents, done)
        if done:
            self.agents = []
        return obs, rewards, terms, truncs, infos

    def render(self):
        text = f"t={self._t} " + " ".join(f"{q}" for q in self._q)
        if self.render_mode == "ansi":
            return text
        if self.render_mode == "human":
            print(text)
            return None
        if self.render_mode == "rgb_array":
            img = np.full((10, 10 * self.nodes, 3), 255, np.uint8)
            for i, q in enumerate(self._q):
                img[10 - 2 * q:, 10 * i: 10 * i + 8] = (30, 60, 200)
            return img
        return None


class RelayLocalSimulator(LocalSimulator):
    """``n_envs`` copies of each of ``agents``' nodes alone (see the module docstring)."""

    def __init__(self, agents="node_2", n_envs=1, nodes=5, capacity=4, arrival_probability=0.3, max_cycles=50):
        self.agents = agent_list(agents)
        self.n_envs = check_n_envs(n_envs)
        self.regions = tuple(region_spec(a, nodes, capacity, arrival_probability) for a in self.agents)
        self.capacity, self.p, self.max_cycles = capacity, float(arrival_probability), max_cycles
        self.observation_space = spaces.Box(0.0, 1.0, (capacity + 1,), np.float32)
        self.action_space = spaces.Discrete(2)
        self._first = np.repeat([_index(a, nodes) == 0 for a in self.agents], self.n_envs)
        self._streams, self._q = CopyStreams(self.agents, self.n_envs, 1), np.zeros(self.n_copies, np.int64)

    def _views(self):
        onehot = np.eye(self.capacity + 1, dtype=np.uint8)[self._q]
        return onehot.astype(np.float32), {"dset": onehot, "full": onehot.copy()}

    def reset(self, seed=None):
        if seed is not None:
            self._streams.seed(seed)
        self._q[:] = 0
        return self._views()

    def step(self, actions, influences):
        actions = np.asarray(actions).reshape(self.n_copies)
        influences = np.asarray(influences).reshape(self.n_copies, 1)
        if not np.isin(actions, (0, 1)).all() or not np.isin(influences, (0, 1)).all():
            raise ValueError("actions and influences must be 0 or 1")
        forward = np.where(self._q > 0, actions, 0)
        arrival = (self._streams.next()[:, 0] < self.p) & self._first
        self._q = np.minimum(self._q - forward + arrival + influences[:, 0], self.capacity)
        obs, dsets = self._views()
        return obs, (-self._q / self.capacity).astype(np.float64), dsets


DOMAIN = Domain(
    env_id=ENV_ID,
    description="packets travel down a line of relay nodes (test-only toy domain)",
    parallel_env=lambda **options: RelayEnv(**options),
    local_simulator=lambda agents, n_envs=1, **options: RelayLocalSimulator(
        agents, n_envs, **{k: v for k, v in options.items() if k not in ("learners", "scripted_learners", "render_mode")}),
    region_spec=region_spec,
    possible_agents=possible_agents,
    observation_space=spaces.Box(0.0, 1.0, (5,), np.float32),
    action_space=spaces.Discrete(2),
    default_agents=("node_2",),
    default_predictor="mlp",
    episode_length=50,
    agent_options=("nodes",),
    null_influence=0,
    replay_agreement=1.0,  # node 2's only randomness is its left neighbour's packets
    # the core is all a domain must give; this extra only makes the tests' study small
    extras={"study": StudySettings(budget=2_000, ppo_steps_per_second={"gs": 3000.0, "ials": 3000.0},
                                   multi_agent_budget=1_000)},
)
