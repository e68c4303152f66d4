"""The batched PPO against references computed independently: GAE by hand, one update against
a per-agent PPO written with SB3's formulas in plain torch, reward scaling against SB3's
``VecNormalize``. Each would fail if advantage normalisation, the clipped surrogate, GAE's
lambda, the value loss, the entropy bonus, the per-agent gradient clip or the reward scale
were wrong."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from ials_zoo.core.streams import agent_key
from ials_zoo.learners.batched_ppo import BatchedPPO, PPOConfig, RewardScale, gae


def test_gae_matches_hand_computed_advantages_with_an_episode_end():
    gamma, lam = 0.9, 0.5
    rewards = np.array([1.0, 2.0, 0.5, -1.0])
    values = np.array([0.3, -0.2, 0.8, 0.1])
    dones = np.array([0.0, 1.0, 0.0, 0.0])  # the episode ends after step 1 (then a new one starts)
    last_value = 0.7
    # by hand: deltas, then A_t = delta_t + gamma * lam * (1 - done_t) * A_{t+1}
    d3 = -1.0 + 0.9 * 0.7 - 0.1              # = -0.47
    d2 = 0.5 + 0.9 * 0.1 - 0.8               # = -0.21
    d1 = 2.0 + 0.0 - (-0.2)                  # = 2.2 (episode ended: no bootstrap)
    d0 = 1.0 + 0.9 * (-0.2) - 0.3            # = 0.52
    a3 = d3
    a2 = d2 + 0.45 * a3                      # = -0.4215
    a1 = d1                                  # the end cuts the trace
    a0 = d0 + 0.45 * a1                      # = 1.51
    expected = np.array([a0, a1, a2, a3])
    shape = (4, 1, 1)
    adv, ret = gae(rewards.reshape(shape), values.reshape(shape), dones.reshape(shape),
                   np.array([[last_value]]), gamma, lam)
    np.testing.assert_allclose(adv.ravel(), expected, rtol=1e-12)
    np.testing.assert_allclose(ret.ravel(), expected + values, rtol=1e-12)


class _ReferenceAgent(torch.nn.Module):
    """One agent's actor and critic, as SB3's ``MlpPolicy`` with separate tanh networks; a
    recurrent learner's heads first read the frames through a ``torch.nn.GRU`` each."""

    def __init__(self, learner: BatchedPPO, k: int):
        super().__init__()
        self.heads = torch.nn.ModuleDict()
        self.grus = torch.nn.ModuleDict()
        self.frames, self.frame_size = learner.cfg.frames, learner.frame_size
        for head in ("pi", "vf"):
            if learner.recurrent:
                H, Hp, F = learner.recurrent, -(-learner.recurrent // 8) * 8, learner.frame_size
                gru = torch.nn.GRU(F, H, batch_first=True)

                def gates(name, rows=None):
                    t = learner.params[f"{head}.gru.{name}"][k]
                    t = t[:rows] if rows else t
                    return torch.cat([t[..., g * Hp:g * Hp + H] for g in range(3)], dim=-1)

                with torch.no_grad():
                    gru.weight_ih_l0.copy_(gates("weight_ih", F).T)
                    gru.weight_hh_l0.copy_(gates("weight_hh", H).T)
                    gru.bias_ih_l0.copy_(gates("bias_ih"))
                    gru.bias_hh_l0.copy_(gates("bias_hh"))
                self.grus[head] = gru
            sizes = learner._sizes[head]
            layers = []
            for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
                lin = torch.nn.Linear(a, b)
                with torch.no_grad():
                    lin.weight.copy_(learner.params[f"{head}.{i}.weight"][k, :a, :b].T)
                    lin.bias.copy_(learner.params[f"{head}.{i}.bias"][k, :b])
                layers.append(lin)
                if i < len(sizes) - 2:
                    layers.append(torch.nn.Tanh())
            self.heads[head] = torch.nn.Sequential(*layers)

    def _read(self, head, x):
        if head not in self.grus:
            return x
        _, h = self.grus[head](x.reshape(len(x), self.frames, self.frame_size))
        return h[0]

    def forward(self, x):
        return self.heads["pi"](self._read("pi", x)), self.heads["vf"](self._read("vf", x))[..., 0]


def _reference_update(agent: _ReferenceAgent, cfg: PPOConfig, perm_rng, obs, actions, logp_old, returns, adv):
    """SB3's ``PPO.train`` for one agent (clip_range_vf None, normalize_advantage as cfg)."""
    opt = torch.optim.Adam(agent.parameters(), lr=cfg.learning_rate, eps=1e-5)
    obs, actions = torch.as_tensor(obs, dtype=torch.float32), torch.as_tensor(actions)
    logp_old, returns = torch.as_tensor(logp_old, dtype=torch.float32), torch.as_tensor(returns, dtype=torch.float32)
    adv_all = torch.as_tensor(adv, dtype=torch.float32)
    n = len(actions)
    clip_fractions = []
    for _ in range(cfg.n_epochs):
        perm = torch.as_tensor(perm_rng.permutation(n))
        for start in range(0, n, cfg.batch_size):
            idx = perm[start:start + cfg.batch_size]
            logits, values = agent(obs[idx])
            dist = torch.distributions.Categorical(logits=logits)
            log_prob = dist.log_prob(actions[idx])
            advantages = adv_all[idx]
            if cfg.normalize_advantage:
                advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
            ratio = torch.exp(log_prob - logp_old[idx])
            policy_loss_1 = advantages * ratio
            policy_loss_2 = advantages * torch.clamp(ratio, 1 - cfg.clip_range, 1 + cfg.clip_range)
            policy_loss = -torch.min(policy_loss_1, policy_loss_2).mean()
            clip_fractions.append(torch.mean((torch.abs(ratio - 1) > cfg.clip_range).float()).item())
            value_loss = torch.nn.functional.mse_loss(returns[idx], values)
            entropy_loss = -torch.mean(dist.entropy())
            loss = policy_loss + cfg.ent_coef * entropy_loss + cfg.vf_coef * value_loss
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(agent.parameters(), cfg.max_grad_norm)
            opt.step()
    return float(np.mean(clip_fractions))


@pytest.mark.parametrize("normalize_advantage,recurrent", [(True, 0), (False, 0), (True, 5)])
def test_one_update_matches_a_per_agent_sb3_reference(normalize_advantage, recurrent):
    """Weights after one update (2 epochs of 4 minibatches), and the clip fraction, equal a
    plain torch PPO per agent run with SB3's formulas, for each of 3 agents in one batch; with
    a recurrent encoder, ``torch.nn.GRU`` over the frames is the reference (7 inputs read as
    a sequence of 7 one-number frames)."""
    agents = ["tls_0", "robot_7", "x"]
    cfg = PPOConfig(n_steps=8, n_envs=4, batch_size=8, n_epochs=2, learning_rate=3e-3, anneal_lr=False,
                    clip_range=0.1, ent_coef=0.05, vf_coef=0.7, max_grad_norm=0.5, hidden=(13, 11),
                    normalize_advantage=normalize_advantage, recurrent_hidden=recurrent, frames=7 if recurrent else 1)
    learner = BatchedPPO(agents, 7, 3, cfg, seed=11)
    references = [_ReferenceAgent(learner, k) for k in range(len(agents))]
    rng = np.random.default_rng(3)
    A, N = len(agents), 32
    obs = rng.standard_normal((A, N, 7)).astype(np.float32)
    actions = rng.integers(3, size=(A, N))
    with torch.no_grad():
        logits, _ = learner.forward(learner._input(obs))
        logp_now = torch.log_softmax(logits, -1).gather(-1, torch.as_tensor(actions)[..., None])[..., 0].numpy()
    # old log-probabilities off by up to +-0.3: many ratios fall outside the clip range
    logp_old = (logp_now + rng.uniform(-0.3, 0.3, size=(A, N))).astype(np.float32)
    returns = (rng.standard_normal((A, N)) * 5.0).astype(np.float32)  # large: the gradient clip binds
    adv = (rng.standard_normal((A, N)) * 3.0 + 1.0).astype(np.float32)
    values_old = rng.standard_normal((A, N)).astype(np.float32)
    stats = learner.update(obs, actions, logp_old, returns, adv, values_old)
    clip_fractions = []
    for k, (agent, ref) in enumerate(zip(agents, references)):
        perm_rng = np.random.default_rng([11, agent_key(agent), agent_key("minibatches")])
        clip_fractions.append(_reference_update(ref, cfg, perm_rng, obs[k], actions[k], logp_old[k], returns[k], adv[k]))
        for head in ("pi", "vf"):
            linears = [m for m in ref.heads[head] if isinstance(m, torch.nn.Linear)]
            for i, lin in enumerate(linears):
                a, b = lin.in_features, lin.out_features
                got = learner.params[f"{head}.{i}.weight"][k, :a, :b].detach().numpy()
                np.testing.assert_allclose(got, lin.weight.detach().numpy().T, atol=2e-5, err_msg=f"{agent} {head}{i}")
                np.testing.assert_allclose(learner.params[f"{head}.{i}.bias"][k, :b].detach().numpy(),
                                           lin.bias.detach().numpy(), atol=2e-5)
        if recurrent:
            exported = learner.actor_layers()[0]
            gru = ref.grus["pi"]
            for got, want in zip(exported, (gru.weight_ih_l0, gru.weight_hh_l0, gru.bias_ih_l0, gru.bias_hh_l0)):
                want = want.detach().numpy()
                np.testing.assert_allclose(got[k], want.T if want.ndim == 2 else want, atol=2e-5,
                                           err_msg=f"{agent} GRU")
    assert 0.1 < np.mean(clip_fractions) < 0.9  # the clip is exercised
    assert stats["clip_fraction"] == pytest.approx(np.mean(clip_fractions), abs=1e-6)


def test_reward_scale_matches_sb3_vecnormalize():
    """Each agent's rewards scaled as SB3's ``VecNormalize(norm_obs=False)`` scales them, with
    the returns reset at episode ends; agents do not share statistics."""
    from stable_baselines3.common.running_mean_std import RunningMeanStd

    gamma, n_envs = 0.99, 3
    rng = np.random.default_rng(0)
    scale = RewardScale(2, n_envs, gamma)
    sb3 = [RunningMeanStd(shape=()) for _ in range(2)]
    sb3_returns = np.zeros((2, n_envs))
    for t in range(50):
        rewards = np.stack([rng.uniform(0, 1, n_envs), rng.uniform(0, 40, n_envs)])
        done = t % 10 == 9
        got = scale(rewards, done)
        for k in range(2):
            sb3_returns[k] = sb3_returns[k] * gamma + rewards[k]
            sb3[k].update(sb3_returns[k])
            expected = rewards[k] / np.sqrt(sb3[k].var + 1e-8)
            np.testing.assert_allclose(got[k], expected, rtol=1e-10)
            if done:
                sb3_returns[k] = 0.0
    # the second agent's rewards are 40x larger: so is its scale, not the first agent's
    assert scale.var[1] > 100 * scale.var[0]


def test_reward_scale_survives_a_checkpoint():
    scale = RewardScale(1, 2, 0.9)
    scale(np.ones((1, 2)), False)
    copy = RewardScale(1, 2, 0.9)
    copy.load_state_dict(scale.state_dict())
    r = np.full((1, 2), 3.0)
    np.testing.assert_array_equal(scale(r, False), copy(r, False))


def _agent_loss(ref, cfg, obs, actions, logp_old, returns, adv):
    """SB3's PPO loss of one agent's minibatch (as in :func:`_reference_update`)."""
    logits, values = ref(obs)
    dist = torch.distributions.Categorical(logits=logits)
    ratio = torch.exp(dist.log_prob(actions) - logp_old)
    if cfg.normalize_advantage:
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
    policy_loss = -torch.min(adv * ratio, adv * torch.clamp(ratio, 1 - cfg.clip_range, 1 + cfg.clip_range)).mean()
    value_loss = torch.nn.functional.mse_loss(returns, values)
    return policy_loss + cfg.ent_coef * -torch.mean(dist.entropy()) + cfg.vf_coef * value_loss


def test_the_shared_ppo_is_one_network_on_every_agents_minibatch_and_its_id():
    """One update of :class:`SharedPPO` equals one plain torch actor-critic (SB3's formulas)
    reading each agent's observation with a one-hot of its id, minimising the mean of the
    agents' minibatch losses with one gradient clip; its policy file's actors are that network."""
    from ials_zoo.learners.batched_ppo import SharedPPO

    agents = ["tls_0", "robot_7", "x"]
    cfg = PPOConfig(n_steps=8, n_envs=4, batch_size=8, n_epochs=2, learning_rate=3e-3, anneal_lr=False,
                    ent_coef=0.05, vf_coef=0.7, max_grad_norm=0.5, hidden=(13, 11))
    learner = SharedPPO(agents, 7, 3, cfg, seed=11)
    ref = _ReferenceAgent(learner, 0)  # the one network (10 inputs: 7 + the id)
    rng = np.random.default_rng(3)
    A, N = len(agents), 32
    obs = rng.standard_normal((A, N, 7)).astype(np.float32)
    actions = rng.integers(3, size=(A, N))
    logp_old = np.log(np.full((A, N), 1 / 3) + rng.uniform(-0.1, 0.1, size=(A, N))).astype(np.float32)
    returns = (rng.standard_normal((A, N)) * 5.0).astype(np.float32)
    adv = (rng.standard_normal((A, N)) * 3.0 + 1.0).astype(np.float32)
    ids = np.repeat(np.eye(A, dtype=np.float32)[:, None], N, 1)
    x = torch.as_tensor(np.concatenate([obs, ids], -1))
    opt = torch.optim.Adam(ref.parameters(), lr=cfg.learning_rate, eps=1e-5)
    perm_rngs = [np.random.default_rng([11, agent_key(a), agent_key("minibatches"), 0]) for a in agents]
    learner.update(obs, actions, logp_old, returns, adv, np.zeros((A, N), np.float32))
    for _ in range(cfg.n_epochs):
        perms = [torch.as_tensor(r.permutation(N)) for r in perm_rngs]
        for start in range(0, N, cfg.batch_size):
            losses = []
            for k in range(A):
                i = perms[k][start:start + cfg.batch_size]
                losses.append(_agent_loss(ref, cfg, x[k, i], torch.as_tensor(actions[k])[i],
                                          torch.as_tensor(logp_old[k])[i], torch.as_tensor(returns[k])[i],
                                          torch.as_tensor(adv[k])[i]))
            opt.zero_grad()
            torch.stack(losses).mean().backward()
            torch.nn.utils.clip_grad_norm_(ref.parameters(), cfg.max_grad_norm)
            opt.step()
    for head in ("pi", "vf"):
        for i, lin in enumerate(m for m in ref.heads[head] if isinstance(m, torch.nn.Linear)):
            a, b = lin.in_features, lin.out_features
            np.testing.assert_allclose(learner.params[f"{head}.{i}.weight"][0, :a, :b].detach().numpy(),
                                       lin.weight.detach().numpy().T, atol=2e-5, err_msg=f"{head}{i}")
    with torch.no_grad():
        want = ref(x)[0].numpy()
    h = obs.astype(np.float64)
    for i, (w, b) in enumerate(learner.actor_layers()):
        h = np.einsum("abi,aio->abo", h, w) + b[:, None]
        h = np.tanh(h) if i < len(learner.actor_layers()) - 1 else h
    np.testing.assert_allclose(h, want, atol=1e-5)
