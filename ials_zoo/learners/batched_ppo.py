"""Independent PPO for many agents in one batched torch program.

Every agent has its own actor and critic (separate MLPs with tanh, as SB3's ``MlpPolicy`` with
``net_arch={"pi": hidden, "vf": hidden}``, each optionally reading its stacked observations
through its own GRU first: ``PPOConfig.recurrent_hidden``) and its own PPO update; their weights are stacked on
a leading agent axis, so a forward pass or an update of all agents is one ``torch.bmm`` per
layer instead of one small model call per agent. Nothing is shared:

* the loss is the sum of the agents' PPO losses and Adam works element-wise, so each agent's
  parameters follow exactly the updates its own optimiser would make;
* gradients are clipped per agent (SB3 clips each model's global norm);
* advantages are normalised per agent and minibatch; minibatches are each agent's own random
  permutation; actions are sampled from each (agent, copy)'s own random stream
  (:class:`ials_zoo.core.streams.CopyStreams`); initial weights come from a generator seeded
  with the run seed and the agent's name.

Random numbers are counter-based: the action streams and the minibatch permutations of
update ``k`` are seeded from ``(seed, k)`` (:func:`~ials_zoo.core.streams.derived_seed`),
so :meth:`BatchedPPO.state_dict` (weights, optimiser, update count, reward scale) is all
a resumed run needs to draw what the uninterrupted run draws.

So an agent's training does not depend on which other agents share the batch (or the process):
DIALS gives the same run with any number of workers. Bitwise, too: every matrix dimension is
zero-padded to a multiple of 8 (:func:`_padded`), with which torch's CPU batched products give
an agent's slice the same bits for any number of agents (checked by the tests; odd widths and
single-column outputs do not, and a different CPU or torch build may round differently, so
the same worker count is the safe way to repeat a run bit for bit). The update follows
SB3's PPO (clipped surrogate, value loss ``vf_coef * MSE`` without clipping, entropy bonus,
``n_epochs`` passes over ``batch_size`` minibatches, linear learning-rate decay, time-limit
bootstrapping ``r_T += gamma V(s_T)``), with optional reward scaling (:class:`RewardScale`,
SB3's ``VecNormalize``). ``tests/test_ppo_reference.py`` checks one update of every agent
against a per-agent PPO written with SB3's formulas in plain torch, GAE against hand-computed
advantages and the reward scale against SB3's; the study's learner comparison checks that it
learns like SB3's PPO.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ials_zoo.core.streams import CopyStreams, agent_key, derived_seed
from ials_zoo.errors import BadInput

ACTION_STREAM_SALT = 2


@dataclass
class PPOConfig:
    """PPO settings (SPEC §3/§6)."""

    n_steps: int = 16
    n_envs: int = 8
    batch_size: int = 64
    n_epochs: int = 3
    learning_rate: float = 2.5e-4
    anneal_lr: bool = True
    clip_range: float = 0.1
    ent_coef: float = 0.01
    vf_coef: float = 1.0
    gamma: float = 0.99
    gae_lambda: float = 0.95
    max_grad_norm: float = 0.5
    hidden: tuple = (256, 128)
    normalize_advantage: bool = True
    normalize_reward: bool = False
    recurrent_hidden: int = 0
    """> 0: actor and critic each read their input through a GRU of this many units, run over
    the ``frames`` stacked observations (oldest first) -- SPEC §6's warehouse policy,
    "recurrent over the last 8 observations"; 0: the MLP reads the frames concatenated."""
    frames: int = 1
    """How many observations the input stacks (the GRU's sequence length)."""


PAD = 8


def _padded(n: int) -> int:
    """``n`` rounded up to a multiple of :data:`PAD`. With every matrix dimension a multiple of
    8, torch's batched matrix products give each agent's slice bitwise the same result for any
    number of agents in the batch (measured: odd widths such as 5 actions or 37 inputs, and
    single-column outputs, round differently with the batch size)."""
    return -(-int(n) // PAD) * PAD


def _orthogonal(rng: np.random.Generator, rows: int, cols: int, gain: float) -> np.ndarray:
    """torch's orthogonal initialisation (QR of a Gaussian matrix, sign-corrected), numpy."""
    a = rng.standard_normal((max(rows, cols), min(rows, cols)))
    q, r = np.linalg.qr(a)
    q *= np.sign(np.diag(r))
    if rows < cols:
        q = q.T
    return (gain * q[:rows, :cols]).astype(np.float32)


class BatchedPPO:
    """Independent PPO learners of ``agents`` (module docstring).

    Args:
        agents: the agents (rows of every array, in this order).
        input_size: what a policy reads (observation width x frame stack).
        n_actions: ``Discrete`` actions.
        cfg: :class:`PPOConfig`.
        seed: the run seed (with each agent's name: its weights, minibatches and actions).
        total_updates: updates over the whole run, for the learning-rate decay.
        action_counts: per agent, how many of the ``n_actions`` it has (agents with their own
            action spaces; the others are masked out), or None (all).
    """

    def __init__(self, agents, input_size: int, n_actions: int, cfg: PPOConfig, seed: int = 0,
                 total_updates: int = 1, action_counts=None):
        import torch

        self.agents = list(agents)
        self.cfg, self.seed = cfg, int(seed)
        self.input_size, self.n_actions = int(input_size), int(n_actions)
        self.action_counts = None if action_counts is None else [int(c) for c in action_counts]
        self._mask = None
        if self.action_counts is not None:
            # a large finite penalty, not -inf: the entropy's p * log p stays 0 * finite
            missing = np.arange(self.n_actions)[None, :] >= np.asarray(self.action_counts)[:, None]
            self._mask = torch.from_numpy(np.where(missing, -1e9, 0.0).astype(np.float32))[:, None, :]
        self.total_updates, self.updates = max(1, int(total_updates)), 0
        A = len(self.agents)
        params = {}
        self._sizes = {}
        self.recurrent = int(cfg.recurrent_hidden)
        if self.recurrent < 0 or cfg.frames < 1 or self.input_size % cfg.frames:
            raise BadInput(f"recurrent_hidden must be >= 0 and the input ({self.input_size}) a whole number of "
                           f"frames ({cfg.frames})")
        self.frame_size = self.input_size // cfg.frames
        for head, out, gain_out in (("pi", n_actions, 0.01), ("vf", 1, 1.0)):
            if self.recurrent:
                params.update(self._gru_params(head))
            sizes = [self.recurrent or self.input_size, *cfg.hidden, out]
            self._sizes[head] = sizes
            for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
                gain = gain_out if i == len(sizes) - 2 else math.sqrt(2)
                # zero-padded to multiples of PAD: the padding stays zero (its gradients are zero)
                w = np.zeros((A, _padded(a), _padded(b)), np.float32)
                for k, ag in enumerate(self.agents):
                    w[k, :a, :b] = _orthogonal(self._rng(ag, f"{head}{i}"), b, a, gain).T
                params[f"{head}.{i}.weight"] = torch.from_numpy(w)
                params[f"{head}.{i}.bias"] = torch.zeros(A, _padded(b))
        self.params = {k: torch.nn.Parameter(v) for k, v in params.items()}
        self.n_layers = len(cfg.hidden) + 1
        self.opt = torch.optim.Adam(self.params.values(), lr=cfg.learning_rate, eps=1e-5, fused=True)
        self.streams = CopyStreams(self.agents, cfg.n_envs, 1, salt=ACTION_STREAM_SALT)
        self._seed_update()
        self.reward_scale = RewardScale(A, cfg.n_envs, cfg.gamma)

    def _gru_params(self, head: str) -> dict:
        """A GRU per agent (torch's gate order r, z, n), each gate's block padded to
        :func:`_padded` units so the padding stays zero; orthogonal weights, zero biases."""
        import torch

        A, H, F = len(self.agents), self.recurrent, self.frame_size
        Hp = _padded(H)
        w_ih = np.zeros((A, _padded(F), 3 * Hp), np.float32)
        w_hh = np.zeros((A, Hp, 3 * Hp), np.float32)
        for k, ag in enumerate(self.agents):
            for g in range(3):
                w_ih[k, :F, g * Hp:g * Hp + H] = _orthogonal(self._rng(ag, f"{head}.gru.ih{g}"), H, F, 1.0).T
                w_hh[k, :H, g * Hp:g * Hp + H] = _orthogonal(self._rng(ag, f"{head}.gru.hh{g}"), H, H, 1.0).T
        return {f"{head}.gru.weight_ih": torch.from_numpy(w_ih), f"{head}.gru.weight_hh": torch.from_numpy(w_hh),
                f"{head}.gru.bias_ih": torch.zeros(A, 3 * Hp), f"{head}.gru.bias_hh": torch.zeros(A, 3 * Hp)}

    def _rng(self, agent: str, what: str, *counters: int) -> np.random.Generator:
        return np.random.default_rng([self.seed, agent_key(agent), agent_key(what), *counters])

    def _seed_update(self) -> None:
        """The random numbers of update ``self.updates``: its rollout's actions, its minibatches."""
        self.streams.seed(derived_seed(self.seed, "update", self.updates))
        self._perm_rngs = [self._rng(a, "minibatches", self.updates) for a in self.agents]

    # -- networks
    def _gru(self, head: str, x):
        """``x [A, B, padded input]`` -> the GRU's last hidden state ``[A, B, padded units]``."""
        import torch

        p = self.params
        A, B = x.shape[0], x.shape[1]
        Fp, Hp = _padded(self.frame_size), _padded(self.recurrent)
        frames = x[..., :self.input_size].reshape(A, B, self.cfg.frames, self.frame_size)
        if Fp != self.frame_size:
            frames = torch.nn.functional.pad(frames, (0, Fp - self.frame_size))
        # the small weights are split by gate, never the large activations: indexing or
        # splitting an activation zero-fills all of it in the backward pass, per slice
        # (measured: 80% of an update)
        w_ih, w_hh = p[f"{head}.gru.weight_ih"].split(Hp, -1), p[f"{head}.gru.weight_hh"].split(Hp, -1)
        b_ih, b_hh = p[f"{head}.gru.bias_ih"].split(Hp, -1), p[f"{head}.gru.bias_hh"].split(Hp, -1)
        flat = frames.reshape(A, -1, Fp)
        gi = [torch.baddbmm(b[:, None], flat, w).reshape(A, B, self.cfg.frames, Hp).unbind(2)
              for w, b in zip(w_ih, b_ih)]
        h = x.new_zeros(A, B, Hp)
        for t in range(self.cfg.frames):
            h_r, h_z, h_n = (torch.baddbmm(b[:, None], h, w) for w, b in zip(w_hh, b_hh))
            r, z = torch.sigmoid(gi[0][t] + h_r), torch.sigmoid(gi[1][t] + h_z)
            n = torch.sigmoid((gi[2][t] + r * h_n) * 2.0) * 2.0 - 1.0  # tanh (see _mlp)
            h = n + z * (h - n)
        return h

    def _mlp(self, head: str, x):
        import torch

        if self.recurrent:
            x = self._gru(head, x)
        for i in range(self.n_layers):
            w, b = self._layer(head, i, x.shape[0])
            x = torch.baddbmm(b[:, None], x, w)
            if i < self.n_layers - 1:
                # tanh(x) = 2 sigmoid(2x) - 1: torch's CPU tanh costs ~10x its sigmoid here
                # (115 vs 12 us on [13, 64, 64]) and was a fifth of a whole PPO update
                x = torch.sigmoid(x * 2.0) * 2.0 - 1.0
        return x

    def _layer(self, head: str, i: int, rows: int):
        """Layer ``i`` of ``head``'s weights and biases for ``rows`` agents: each agent's own."""
        return self.params[f"{head}.{i}.weight"], self.params[f"{head}.{i}.bias"]

    def _input(self, obs):
        import torch

        x = torch.from_numpy(np.asarray(obs, np.float32))
        pad = _padded(self.input_size) - self.input_size
        return torch.nn.functional.pad(x, (0, pad)) if pad else x

    def forward(self, x):
        """``x [A, B, padded input]`` -> ``(logits [A, B, n_actions], values [A, B])``."""
        return self._logits(x), self._mlp("vf", x)[..., 0]

    def act(self, obs: np.ndarray):
        """``obs [A, n_envs, input]`` -> ``(actions, values, log-probabilities)``, each ``[A, n_envs]``."""
        import torch

        with torch.no_grad():
            logits, values = self.forward(self._input(obs))
            logp_all = torch.log_softmax(logits, dim=-1)
            probs = logp_all.exp().numpy().astype(np.float64)
        cum = np.cumsum(probs, axis=-1)
        u = self.streams.next().reshape(cum.shape[0], cum.shape[1], 1)
        last = self.n_actions - 1 if self.action_counts is None else np.asarray(self.action_counts)[:, None] - 1
        actions = np.minimum((cum < u * cum[..., -1:]).sum(axis=-1), last)
        logp = np.take_along_axis(logp_all.numpy(), actions[..., None], axis=-1)[..., 0]
        return actions, values.numpy(), logp

    def values(self, obs: np.ndarray) -> np.ndarray:
        import torch

        with torch.no_grad():
            return self._mlp("vf", self._input(obs))[..., 0].numpy()

    # -- a warm start
    def imitate(self, obs, actions, updates: int, seed: int, returns=None, learning_rate: float | None = None) -> dict:
        """Fit the actors to ``actions [A, N]`` chosen at ``obs [A, N, input]``: cross-entropy in
        ``updates`` minibatches of ``batch_size`` (whole epochs, shuffled), with an Adam of its own
        at ``learning_rate`` (default: the PPO's) (a warm start from a rule:
        :mod:`ials_zoo.baselines.imitation`). With ``returns [A, N]`` (the rule's returns from
        each observation, in the reward scale's units) the critics are fitted to them too, by the
        squared error; else they are left as they are. PPO's optimiser is left as it is. Returns
        the last epoch's mean cross-entropy (``loss``), squared error (``value_loss``, with
        ``returns``) and ``agreement``, the share of the given choices that the actors' likeliest
        action now makes."""
        import torch

        if self.recurrent:
            raise BadInput("imitation fits actors that read one observation: recurrent_hidden must be 0")
        x, chosen = self._input(obs), torch.from_numpy(np.asarray(actions, np.int64))
        target = None if returns is None else torch.from_numpy(np.asarray(returns, np.float32))
        A, N = chosen.shape
        heads = ("pi.",) if target is None else ("pi.", "vf.")
        opt = torch.optim.Adam([v for k, v in self.params.items() if k.startswith(heads)],
                               lr=learning_rate or self.cfg.learning_rate, eps=1e-5)
        rng, rows, bs = np.random.default_rng(seed), torch.arange(A)[:, None], min(self.cfg.batch_size, N)
        for _ in range(max(1, -(-int(updates) // -(-N // bs)))):
            perm, losses, errors = torch.from_numpy(np.stack([rng.permutation(N) for _ in range(A)])), [], []
            for start in range(0, N, bs):
                idx = perm[:, start:start + bs]
                logp = torch.log_softmax(self._logits(x[rows, idx]), dim=-1)
                per_agent = -logp.gather(-1, chosen[rows, idx][..., None])[..., 0].mean(dim=1)
                losses.append(per_agent.mean().item())
                if target is not None:
                    error = ((self._mlp("vf", x[rows, idx])[..., 0] - target[rows, idx]) ** 2).mean(dim=1)
                    errors.append(error.mean().item())
                    per_agent = per_agent + self.cfg.vf_coef * error
                opt.zero_grad(set_to_none=True)
                self._total(per_agent).backward()
                opt.step()
        with torch.no_grad():
            agreement = (self._logits(x).argmax(dim=-1) == chosen).float().mean().item()
        return {"loss": float(np.mean(losses)), "agreement": agreement,
                **({"value_loss": float(np.mean(errors))} if errors else {})}

    def _logits(self, x):
        logits = self._mlp("pi", x)[..., :self.n_actions]
        return logits if self._mask is None else logits + self._mask

    # -- update
    def update(self, obs, actions, logp_old, returns, advantages, values_old) -> dict:
        """One PPO update of every agent from its batch (arrays ``[A, N, ...]``)."""
        import torch

        cfg = self.cfg
        lr = cfg.learning_rate * (1.0 - self.updates / self.total_updates) if cfg.anneal_lr else cfg.learning_rate
        for g in self.opt.param_groups:
            g["lr"] = lr
        A, N = actions.shape
        obs_t = self._input(obs)
        act_t = torch.from_numpy(np.asarray(actions, np.int64))
        logp_t = torch.from_numpy(np.asarray(logp_old, np.float32))
        ret_t = torch.from_numpy(np.asarray(returns, np.float32))
        adv_t = torch.from_numpy(np.asarray(advantages, np.float32))
        rows = torch.arange(A)[:, None]
        stats = {"policy_loss": 0.0, "value_loss": 0.0, "entropy": 0.0, "clip_fraction": 0.0, "approx_kl": 0.0}
        count = 0
        bs = min(cfg.batch_size, N)
        for _ in range(cfg.n_epochs):
            perm = torch.from_numpy(np.stack([r.permutation(N) for r in self._perm_rngs]))
            for start in range(0, N, bs):
                idx = perm[:, start:start + bs]
                logits, values = self.forward(obs_t[rows, idx])
                logp_all = torch.log_softmax(logits, dim=-1)
                logp = logp_all.gather(-1, act_t[rows, idx][..., None])[..., 0]
                adv = adv_t[rows, idx]
                if cfg.normalize_advantage and adv.shape[1] > 1:
                    adv = (adv - adv.mean(dim=1, keepdim=True)) / (adv.std(dim=1, keepdim=True) + 1e-8)
                ratio = torch.exp(logp - logp_t[rows, idx])
                surrogate = torch.min(adv * ratio, adv * torch.clamp(ratio, 1 - cfg.clip_range, 1 + cfg.clip_range))
                policy_loss = -surrogate.mean(dim=1)
                value_loss = ((ret_t[rows, idx] - values) ** 2).mean(dim=1)
                entropy = -(logp_all.exp() * logp_all).sum(dim=-1).mean(dim=1)
                loss = self._total(policy_loss + cfg.vf_coef * value_loss - cfg.ent_coef * entropy)
                self.opt.zero_grad(set_to_none=True)
                loss.backward()
                self._clip_gradients(A)
                self.opt.step()
                with torch.no_grad():
                    stats["policy_loss"] += policy_loss.mean().item()
                    stats["value_loss"] += value_loss.mean().item()
                    stats["entropy"] += entropy.mean().item()
                    stats["clip_fraction"] += ((ratio - 1).abs() > cfg.clip_range).float().mean().item()
                    stats["approx_kl"] += ((ratio - 1) - (logp - logp_t[rows, idx])).mean().item()
                count += 1
        self.updates += 1
        self._seed_update()
        out = {k: v / max(count, 1) for k, v in stats.items()}
        out["learning_rate"] = lr
        return out

    def _total(self, per_agent):
        """The loss minimised: every agent's own, summed (each agent's parameters see only theirs)."""
        return per_agent.sum()

    def _clip_gradients(self, rows: int) -> None:
        """Per-agent global gradient norm, clipped as each agent's own optimiser would."""
        import torch

        with torch.no_grad():
            sq = sum(p.grad.reshape(rows, -1).pow(2).sum(dim=1) for p in self.params.values())
            scale = torch.clamp(self.cfg.max_grad_norm / (sq.sqrt() + 1e-6), max=1.0)
            for p in self.params.values():
                p.grad.mul_(scale.reshape(rows, *([1] * (p.grad.dim() - 1))))

    # -- state and policies
    def state_dict(self) -> dict:
        """Weights, optimiser and counters: tensors and plain containers (``weights_only``)."""
        return {"params": {k: v.detach().clone() for k, v in self.params.items()},
                "optimizer": self.opt.state_dict(), "updates": self.updates,
                "reward_scale": self.reward_scale.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        import torch

        with torch.no_grad():
            for k, v in state["params"].items():
                self.params[k].copy_(v)
        self.opt.load_state_dict(state["optimizer"])
        self.updates = int(state["updates"])
        self._seed_update()
        if "reward_scale" in state:
            self.reward_scale.load_state_dict(state["reward_scale"])

    def actor_layers(self) -> list:
        """The actors' ``[(W [A, in, out], b [A, out]), ...]`` as float32 numpy arrays; with a
        recurrent encoder, the first entry is its GRU's ``(W_ih [A, frame, 3H], W_hh [A, H, 3H],
        b_ih [A, 3H], b_hh [A, 3H])`` (torch's gate order, unpadded)."""
        sizes = self._sizes["pi"]
        gru = []
        if self.recurrent:
            H, Hp, F = self.recurrent, _padded(self.recurrent), self.frame_size

            def gates(name, rows):
                t = self.params[f"pi.gru.{name}"].detach().numpy()
                t = t[:, :rows] if rows else t
                return np.concatenate([t[..., g * Hp:g * Hp + H] for g in range(3)], axis=-1).copy()

            gru = [(gates("weight_ih", F), gates("weight_hh", H), gates("bias_ih", 0), gates("bias_hh", 0))]
        return gru + [(self.params[f"pi.{i}.weight"].detach().numpy()[:, :a, :b].copy(),
                 self.params[f"pi.{i}.bias"].detach().numpy()[:, :b].copy())
                for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:]))]


class SharedPPO(BatchedPPO):
    """One actor-critic shared by every agent: each reads its own observation and a one-hot of
    its place among the agents (its id), so one network can still tell the lights apart. The
    rollouts, minibatches, reward scaling and masks are :class:`BatchedPPO`'s, per agent; the
    loss is the mean of the agents' losses, its gradient clipped as one network's, and the
    policy file holds each agent's actor with its id folded into the first layer's bias (the
    same function of the observation). No GRU."""

    def __init__(self, agents, input_size: int, n_actions: int, cfg: PPOConfig, seed: int = 0,
                 total_updates: int = 1, action_counts=None):
        import torch

        if cfg.recurrent_hidden:
            raise BadInput("one shared actor-critic reads no GRU: --recurrent-hidden must be 0")
        self.obs_width = int(input_size)
        super().__init__(agents, self.obs_width + len(agents), n_actions, replace(cfg, frames=1), seed,
                         total_updates, action_counts)
        # the first agent's initial weights become everyone's
        self.params = {k: torch.nn.Parameter(v.detach()[:1].clone()) for k, v in self.params.items()}
        self.opt = torch.optim.Adam(self.params.values(), lr=cfg.learning_rate, eps=1e-5, fused=True)
        self._ids = torch.eye(len(self.agents))

    def _layer(self, head: str, i: int, rows: int):
        w, b = self.params[f"{head}.{i}.weight"], self.params[f"{head}.{i}.bias"]
        return w.expand(rows, -1, -1), b.expand(rows, -1)

    def _input(self, obs):
        import torch

        x = torch.from_numpy(np.asarray(obs, np.float32))
        x = torch.cat([x, self._ids[:, None, :].expand(x.shape[0], x.shape[1], -1)], dim=-1)
        pad = _padded(self.input_size) - self.input_size
        return torch.nn.functional.pad(x, (0, pad)) if pad else x

    def _total(self, per_agent):
        return per_agent.mean()

    def _clip_gradients(self, rows: int) -> None:
        import torch

        torch.nn.utils.clip_grad_norm_(list(self.params.values()), self.cfg.max_grad_norm)

    def actor_layers(self) -> list:
        """Each agent's actor as :meth:`BatchedPPO.actor_layers` gives them: the shared weights,
        the first layer reading the observation alone, its bias plus the row of the agent's id."""
        sizes, A, n = self._sizes["pi"], len(self.agents), self.obs_width
        out = []
        for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
            w = self.params[f"pi.{i}.weight"].detach().numpy()[0, :a, :b]
            bias = self.params[f"pi.{i}.bias"].detach().numpy()[0, :b]
            if i == 0:
                out.append((np.repeat(w[None, :n], A, 0).copy(), (bias[None] + w[n:n + A]).astype(np.float32)))
            else:
                out.append((np.repeat(w[None], A, 0).copy(), np.repeat(bias[None], A, 0).copy()))
        return out


class RewardScale:
    """Rewards divided by the running standard deviation of each agent's discounted return
    (SB3's ``VecNormalize(norm_reward=True)``, Gymnasium's ``NormalizeReward``), per agent so
    that an agent's numbers do not depend on the batch. Traffic returns reach ~50 in value
    units, and with one gradient-norm clip over actor and critic the critic's loss would
    otherwise scale the policy gradient down."""

    def __init__(self, n_agents: int, n_envs: int, gamma: float, epsilon: float = 1e-8):
        self.gamma, self.epsilon = float(gamma), float(epsilon)
        self.returns = np.zeros((n_agents, n_envs))
        self.mean = np.zeros(n_agents)
        self.var = np.ones(n_agents)
        self.count = 1e-4

    def __call__(self, rewards: np.ndarray, done: bool) -> np.ndarray:
        """Scale ``rewards [A, n]`` of one step (updating the statistics first)."""
        self.returns = self.returns * self.gamma + rewards
        self._update(self.returns)
        scaled = rewards / np.sqrt(self.var + self.epsilon)[:, None]
        if done:
            self.returns[:] = 0.0
        return scaled

    def _update(self, x: np.ndarray) -> None:
        # Chan et al.'s parallel update, as SB3's RunningMeanStd, with one count for all agents
        batch_mean, batch_var, n = x.mean(axis=1), x.var(axis=1), x.shape[1]
        delta, total = batch_mean - self.mean, self.count + n
        self.mean = self.mean + delta * n / total
        m2 = self.var * self.count + batch_var * n + delta ** 2 * self.count * n / total
        self.var, self.count = m2 / total, total

    def state_dict(self) -> dict:
        return {"returns": self.returns.tolist(), "mean": self.mean.tolist(), "var": self.var.tolist(),
                "count": self.count}

    def load_state_dict(self, state: dict) -> None:
        self.returns = np.asarray(state["returns"], float)
        self.mean, self.var = np.asarray(state["mean"], float), np.asarray(state["var"], float)
        self.count = float(state["count"])


def gae(rewards, values, dones, last_values, gamma: float, lam: float):
    """Generalised advantage estimates for arrays ``[T, A, n]`` (``dones[t]``: the episode
    ended after step t; truncation is bootstrapped in ``rewards`` beforehand)."""
    T = rewards.shape[0]
    adv = np.zeros_like(rewards)
    last = np.zeros_like(last_values)
    for t in reversed(range(T)):
        next_values = last_values if t == T - 1 else values[t + 1]
        nonterminal = 1.0 - dones[t]
        delta = rewards[t] + gamma * next_values * nonterminal - values[t]
        last = delta + gamma * lam * nonterminal * last
        adv[t] = last
    return adv, adv + values


__all__ = ["BatchedPPO", "PPOConfig", "RewardScale", "SharedPPO", "gae"]
