"""Independent DQN for many agents in one batched torch program (RESCO's IDQN).

Every agent has its own Q-network (an MLP with ReLU), its own target network, replay buffer,
epsilon-greedy exploration and Adam; their weights are stacked on a leading agent axis, so a
forward pass or an update of all agents is one ``torch.bmm`` per layer. Nothing is shared: the
loss is the sum of the agents' losses and Adam works element-wise, so each agent's parameters
follow exactly the updates its own optimiser would make.

The settings are RESCO's (``resco_benchmark/config/agent_config.py`` and
``agents/pfrl_dqn.py``, read from its code; pfrl's ``DQN`` defaults where RESCO sets nothing):
minibatches of 32 from a replay buffer of 10,000 transitions, gamma 0.99, Adam at torch's
default learning rate (1e-3), one update per transition once the buffer holds a minibatch, a
hard target update every 500 transitions, the Huber loss (pfrl's ``clip_delta``) averaged over
the minibatch, epsilon falling linearly from 1 to 0 over 80% of the run. Two differences,
both deliberate:

* a time limit is not a terminal state: its transition bootstraps from the last observation
  (RESCO passes the episode's end to pfrl as terminal);
* the network is dense (RESCO's IDQN opens with a 2x2 convolution over the lanes x features of
  its ``drq`` observation, a layout only its traffic observation has).

Random numbers are counter-based: the exploration at transition ``t`` and the minibatches of
update ``k`` are drawn from ``(seed, t)`` and ``(seed, k)``
(:func:`~ials_zoo.core.streams.derived_seed`), so :meth:`BatchedDQN.state_dict` (weights,
target, optimiser, buffer, counters) is all a resumed run needs to continue bit for bit.
``tests/test_dqn.py`` checks the targets and one update against a hand computation and that
the learner solves a small MDP whose optimal values are known.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ials_zoo.core.streams import agent_key, derived_seed
from ials_zoo.errors import BadInput
from ials_zoo.learners.rollout import SeededEpisodes


@dataclass
class DQNConfig:
    """DQN settings: RESCO's IDQN (module docstring)."""

    batch_size: int = 32
    gamma: float = 0.99
    learning_rate: float = 1e-3
    buffer_size: int = 10_000
    learning_starts: int = 32
    train_every: int = 1
    target_update: int = 500
    eps_start: float = 1.0
    eps_end: float = 0.0
    eps_fraction: float = 0.8
    hidden: tuple = (64, 64)
    huber: bool = True


def check_dqn_config(cfg: DQNConfig) -> None:
    """Clear errors for settings no DQN can run with, each named by its flag."""
    for name in ("batch_size", "buffer_size", "train_every", "target_update"):
        if getattr(cfg, name) < 1:
            raise BadInput(f"--{name.replace('_', '-')} must be >= 1, got {getattr(cfg, name)}")
    if cfg.buffer_size < cfg.batch_size:
        raise BadInput(f"--buffer-size ({cfg.buffer_size}) must hold at least one minibatch (--batch-size "
                       f"{cfg.batch_size})")
    if cfg.buffer_size > 10_000_000:
        raise BadInput(f"--buffer-size {cfg.buffer_size:,}: at most 10,000,000 transitions per agent")
    if cfg.learning_starts < cfg.batch_size:
        raise BadInput(f"--learning-starts ({cfg.learning_starts}) must be at least --batch-size ({cfg.batch_size})")
    for name in ("eps_start", "eps_end"):
        if not 0.0 <= getattr(cfg, name) <= 1.0:
            raise BadInput(f"--{name.replace('_', '-')} must be in [0, 1], got {getattr(cfg, name)}")
    if not 0.0 < cfg.eps_fraction <= 1.0:
        raise BadInput(f"--eps-fraction must be in (0, 1], got {cfg.eps_fraction}")
    if not 0.0 <= cfg.gamma <= 1.0:
        raise BadInput(f"--gamma must be in [0, 1], got {cfg.gamma}")
    if not (cfg.learning_rate > 0 and math.isfinite(cfg.learning_rate)):
        raise BadInput(f"--learning-rate must be a positive number, got {cfg.learning_rate}")


class ReplayBuffers:
    """One replay buffer per agent, stacked ``[A, capacity, ...]``: every agent adds one
    transition per copy at every step, so one write position serves all of them."""

    def __init__(self, agents: int, capacity: int, width: int):
        self.capacity, self.pos, self.size = int(capacity), 0, 0
        self.obs = np.zeros((agents, self.capacity, width), np.float32)
        self.next_obs = np.zeros_like(self.obs)
        self.actions = np.zeros((agents, self.capacity), np.int64)
        self.rewards = np.zeros((agents, self.capacity), np.float32)
        self.terminal = np.zeros((agents, self.capacity), np.float32)

    def add(self, x, a, r, x2, terminal: bool) -> None:
        """One transition of every agent (arrays ``[A, ...]``)."""
        i = self.pos
        self.obs[:, i], self.next_obs[:, i], self.actions[:, i] = x, x2, a
        self.rewards[:, i], self.terminal[:, i] = r, float(terminal)
        self.pos = (i + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, rng: np.random.Generator, batch: int):
        """Each agent's own ``batch`` indices, uniformly among the stored transitions."""
        idx = rng.integers(self.size, size=(self.obs.shape[0], batch))
        rows = np.arange(self.obs.shape[0])[:, None]
        return (self.obs[rows, idx], self.actions[rows, idx], self.rewards[rows, idx], self.next_obs[rows, idx],
                self.terminal[rows, idx])

    def state_dict(self) -> dict:
        import torch

        n = self.size
        return {"pos": self.pos, "size": n, **{k: torch.from_numpy(getattr(self, k)[:, :n].copy())
                                                for k in ("obs", "next_obs", "actions", "rewards", "terminal")}}

    def load_state_dict(self, state: dict) -> None:
        n = int(state["size"])
        for k in ("obs", "next_obs", "actions", "rewards", "terminal"):
            getattr(self, k)[:, :n] = state[k].numpy()
        self.pos, self.size = int(state["pos"]), n


class BatchedDQN:
    """Independent DQN learners of ``agents`` (module docstring).

    Args:
        agents: the agents (rows of every array, in this order).
        input_size: what a Q-network reads (observation width x frame stack).
        n_actions: ``Discrete`` actions.
        cfg: :class:`DQNConfig`.
        seed: the run seed (with each agent's name: its initial weights).
        total_steps: transitions per agent over the whole run, for epsilon's schedule.
        action_counts: per agent, how many of the ``n_actions`` it has (the others are never
            chosen, explored or bootstrapped from), or None (all).
    """

    def __init__(self, agents, input_size: int, n_actions: int, cfg: DQNConfig, seed: int = 0,
                 total_steps: int = 1, action_counts=None):
        import torch

        check_dqn_config(cfg)
        self.agents, self.cfg, self.seed = list(agents), cfg, int(seed)
        self.input_size, self.n_actions = int(input_size), int(n_actions)
        counts = [self.n_actions] * len(self.agents) if action_counts is None else [int(c) for c in action_counts]
        self.counts = np.asarray(counts)
        self._invalid = torch.from_numpy(np.arange(self.n_actions)[None, :] >= self.counts[:, None])[:, None, :]
        self.decay_steps = max(1.0, cfg.eps_fraction * int(total_steps))
        self.steps = self.updates = 0
        self.sizes = [self.input_size, *cfg.hidden, self.n_actions]
        self.params = {k: torch.nn.Parameter(torch.from_numpy(v)) for k, v in self._initial_weights().items()}
        self.target = {k: v.detach().clone() for k, v in self.params.items()}
        self.opt = torch.optim.Adam(list(self.params.values()), lr=cfg.learning_rate)
        self.buffers = self._make_buffers()

    def _make_buffers(self):
        return ReplayBuffers(len(self.agents), self.cfg.buffer_size, self.input_size)

    def _networks(self) -> list[str]:
        """Whose weights the learner holds, one row each: every agent's own."""
        return self.agents

    def _initial_weights(self) -> dict:
        """torch's ``nn.Linear`` initialisation (uniform in +-1/sqrt(fan_in)), from a generator
        seeded with the run seed and the agent's name."""
        out = {}
        for i, (a, b) in enumerate(zip(self.sizes[:-1], self.sizes[1:])):
            bound = 1.0 / math.sqrt(a)
            ws, bs = [], []
            for agent in self._networks():
                rng = np.random.default_rng([self.seed, agent_key(agent), i])
                ws.append(rng.uniform(-bound, bound, (a, b)))
                bs.append(rng.uniform(-bound, bound, b))
            out[f"{i}.weight"] = np.asarray(ws, np.float32)
            out[f"{i}.bias"] = np.asarray(bs, np.float32)
        return out

    def q_values(self, x, target: bool = False, invalid=None):
        """``Q [A, N, n_actions]`` of inputs ``x [A, N, input_size]`` (a torch tensor); the
        actions an agent lacks (``invalid``, default: row ``i``'s are agent ``i``'s) at -inf."""
        h = self._forward(x, self.target if target else self.params)
        return h.masked_fill(self._invalid if invalid is None else invalid, -math.inf)

    def _forward(self, x, p):
        import torch

        h = x
        for i in range(len(self.sizes) - 1):
            h = torch.baddbmm(p[f"{i}.bias"][:, None, :], h, p[f"{i}.weight"])
            if i < len(self.sizes) - 2:
                h = torch.relu(h)
        return h

    def epsilon(self, steps: int | None = None) -> float:
        """Exploration at transition ``steps`` (default: now): linear from ``eps_start`` to
        ``eps_end`` over ``eps_fraction`` of the run, then ``eps_end``."""
        t = self.steps if steps is None else steps
        frac = min(1.0, t / self.decay_steps)
        return self.cfg.eps_start + frac * (self.cfg.eps_end - self.cfg.eps_start)

    def greedy(self, x) -> np.ndarray:
        """Each agent's best action for each row of ``x [A, N, input_size]`` (numpy)."""
        import torch

        with torch.no_grad():
            return self.q_values(torch.as_tensor(np.asarray(x, np.float32))).argmax(-1).numpy()

    def act(self, x) -> np.ndarray:
        """Epsilon-greedy actions ``[A, n]`` for observations ``x [A, n, input_size]``."""
        rng = np.random.default_rng(derived_seed(self.seed, "dqn-act", self.steps))
        explore = rng.random(x.shape[:2]) < self.epsilon()
        random = np.floor(rng.random(x.shape[:2]) * self.counts[:, None]).astype(np.int64)
        return np.where(explore, random, self.greedy(x))

    def observe(self, x, a, r, x2, terminal: bool = False) -> list[dict]:
        """Store each copy's transition (arrays ``[A, n, ...]``) and, transition by transition,
        train and sync the target as the schedule says; returns the updates' statistics."""
        stats = []
        for j in range(np.asarray(a).shape[1]):
            self.buffers.add(x[:, j], a[:, j], r[:, j], x2[:, j], terminal)
            self.steps += 1
            if self.buffers.size >= self.cfg.learning_starts and self.steps % self.cfg.train_every == 0:
                stats.append(self.update())
            if self.steps % self.cfg.target_update == 0:
                self.sync_target()
        return stats

    def td_targets(self, r, x2, terminal, invalid=None):
        """``r + gamma (1 - terminal) max_a' Q_target(x2, a')`` (torch tensors ``[A, B]``)."""
        import torch

        with torch.no_grad():
            best = self.q_values(x2, target=True, invalid=invalid).max(-1).values
        return r + self.cfg.gamma * (1.0 - terminal) * best

    def _minibatch(self):
        """The update's minibatch (torch tensors ``[A, B, ...]``) and the actions its rows lack."""
        import torch

        rng = np.random.default_rng(derived_seed(self.seed, "dqn-update", self.updates))
        return (*(torch.from_numpy(v) for v in self.buffers.sample(rng, self.cfg.batch_size)), None)

    def update(self) -> dict:
        """One gradient step of every agent on its own minibatch."""
        import torch

        x, a, r, x2, term, invalid = self._minibatch()
        target = self.td_targets(r, x2, term, invalid)
        q = self.q_values(x, invalid=invalid).gather(-1, a[..., None])[..., 0]
        loss_fn = torch.nn.functional.smooth_l1_loss if self.cfg.huber else torch.nn.functional.mse_loss
        per_agent = loss_fn(q, target, reduction="none").mean(-1)
        self.opt.zero_grad()
        per_agent.sum().backward()
        self.opt.step()
        self.updates += 1
        return {"loss": float(per_agent.detach().mean()), "q_mean": float(q.detach().mean())}

    def sync_target(self) -> None:
        for k, v in self.params.items():
            self.target[k] = v.detach().clone()

    # -- state and policies
    def state_dict(self) -> dict:
        """Everything a resumed run continues from: tensors and plain containers (``weights_only``)."""
        return {"params": {k: v.detach().clone() for k, v in self.params.items()},
                "target": {k: v.clone() for k, v in self.target.items()}, "optimizer": self.opt.state_dict(),
                "steps": self.steps, "updates": self.updates, "buffers": self.buffers.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        import torch

        with torch.no_grad():
            for k, v in state["params"].items():
                self.params[k].copy_(v)
        self.target = {k: v.clone() for k, v in state["target"].items()}
        self.opt.load_state_dict(state["optimizer"])
        self.steps, self.updates = int(state["steps"]), int(state["updates"])
        self.buffers.load_state_dict(state["buffers"])

    def q_layers(self) -> list:
        """The Q-networks' ``[(W [A, in, out], b [A, out]), ...]`` as float32 numpy arrays."""
        rows = np.zeros(len(self.agents), np.int64) if len(self._networks()) == 1 else np.arange(len(self.agents))
        return [(self.params[f"{i}.weight"].detach().numpy()[rows].copy(),
                 self.params[f"{i}.bias"].detach().numpy()[rows].copy()) for i in range(len(self.sizes) - 1)]


class PooledReplay:
    """One replay buffer for every agent's transitions (a shared DQN's): each step adds one
    transition of every agent, and a row remembers whose it is (the actions that agent has)."""

    KEYS = ("obs", "next_obs", "actions", "rewards", "terminal", "agent")

    def __init__(self, capacity: int, width: int):
        self.capacity, self.pos, self.size = int(capacity), 0, 0
        self.obs = np.zeros((self.capacity, width), np.float32)
        self.next_obs = np.zeros_like(self.obs)
        self.actions = np.zeros(self.capacity, np.int64)
        self.rewards = np.zeros(self.capacity, np.float32)
        self.terminal = np.zeros(self.capacity, np.float32)
        self.agent = np.zeros(self.capacity, np.int64)

    def add(self, x, a, r, x2, terminal: bool) -> None:
        """One transition of every agent (arrays ``[A, ...]``), in agent order."""
        rows = (self.pos + np.arange(len(a))) % self.capacity
        self.obs[rows], self.next_obs[rows], self.actions[rows] = x, x2, a
        self.rewards[rows], self.terminal[rows], self.agent[rows] = r, float(terminal), np.arange(len(a))
        self.pos = int(rows[-1] + 1) % self.capacity
        self.size = min(self.size + len(a), self.capacity)

    def sample(self, rng: np.random.Generator, batch: int):
        """``batch`` rows, uniformly among the stored transitions: arrays ``[1, batch, ...]`` and
        the rows' agents ``[batch]``."""
        idx = rng.integers(self.size, size=batch)
        return (*(getattr(self, k)[idx][None] for k in ("obs", "actions", "rewards", "next_obs", "terminal")),
                self.agent[idx])

    def state_dict(self) -> dict:
        import torch

        n = self.size
        return {"pos": self.pos, "size": n, **{k: torch.from_numpy(getattr(self, k)[:n].copy()) for k in self.KEYS}}

    def load_state_dict(self, state: dict) -> None:
        n = int(state["size"])
        for k in self.KEYS:
            getattr(self, k)[:n] = state[k].numpy()
        self.pos, self.size = int(state["pos"]), n


class SharedDQN(BatchedDQN):
    """One DQN shared by every agent: RESCO's MPLight learner (pfrl's DQN under its
    ``SharedAgent``, ``agents/pfrl_dqn.py``). Every agent acts with the same Q-network on its
    own observation and adds its transitions to one replay buffer of ``buffer_size``
    transitions; one update on a minibatch of ``batch_size`` from it and one epsilon per step of
    every agent, the target network copied every ``target_update`` such steps (RESCO:
    ``update_interval`` and ``target_update_interval`` times the number of lights). An agent
    never chooses nor bootstraps from an action it lacks (its row's mask)."""

    def _make_buffers(self):
        if self.cfg.buffer_size < len(self.agents):
            raise BadInput(f"--buffer-size ({self.cfg.buffer_size}) must hold one step of every agent "
                           f"({len(self.agents)} transitions)")
        return PooledReplay(self.cfg.buffer_size, self.input_size)

    def _networks(self) -> list[str]:
        return ["shared"]

    def _forward(self, x, p):
        rows, n = x.shape[0], x.shape[1]  # every agent's rows through the one network
        return super()._forward(x.reshape(1, rows * n, x.shape[2]), p).reshape(rows, n, -1)

    def _minibatch(self):
        import torch

        rng = np.random.default_rng(derived_seed(self.seed, "dqn-update", self.updates))
        *arrays, agent = self.buffers.sample(rng, self.cfg.batch_size)
        x, a, r, x2, term = (torch.from_numpy(v) for v in arrays)
        return x, a, r, x2, term, self._invalid[torch.from_numpy(agent), 0][None]


class DQNTrainer(SeededEpisodes):
    """Trains ``learner`` on a multi-agent vector env (:mod:`ials_zoo.learners.rollout`'s
    interface), one step of every copy at a time, over reproducible episodes
    (:class:`~ials_zoo.learners.rollout.SeededEpisodes`: a resume replays the episode in
    flight). Episodes end by time limit, whose last transition bootstraps (module docstring)."""

    def __init__(self, learner: BatchedDQN, env, frame_stack: int = 1, seed: int = 0):
        if list(env.agents) != list(learner.agents):
            raise BadInput("the learner and the env must hold the same agents")
        self.learner = learner
        super().__init__(env, frame_stack, int(seed))

    def step(self) -> list[dict]:
        """One step of every copy: act, store, learn; returns the updates' statistics."""
        a = self.learner.act(self.x)
        obs, r, done = self.env.step(a)
        r = np.asarray(r, np.float32)
        x2 = self.stack.push(obs)
        self.actions.append(np.asarray(a, np.int64))
        self.running += r
        self.steps += 1
        stats = self.learner.observe(self.x, a, r, x2, terminal=False)  # a time limit: bootstrap
        if done:
            self._end_episode()
        else:
            self.x = x2
        return stats


__all__ = ["BatchedDQN", "DQNConfig", "DQNTrainer", "PooledReplay", "ReplayBuffers", "SharedDQN", "check_dqn_config"]
