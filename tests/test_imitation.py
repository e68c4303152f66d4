"""The warm start from a rule (ials_zoo.baselines.imitation): the actors fitted by
cross-entropy make a known rule's choices, masked actions never among them; the demonstrations
pair each observation with the rule's choice at it; a warm-started run records its fit and
resumes bitwise (tests/test_exact_resume.py)."""

from __future__ import annotations

import numpy as np
import pytest

from ials_zoo.learners.batched_ppo import BatchedPPO, PPOConfig, SharedPPO

COUNTS = [2, 3, 4]  # agents with fewer actions than the widest: the rest are masked


def _rule(obs: np.ndarray) -> np.ndarray:
    """A known rule: each agent's likeliest of its own actions is its largest feature."""
    return np.stack([np.argmax(obs[k, :, :c], axis=-1) for k, c in enumerate(COUNTS)])


@pytest.mark.parametrize("learner_cls", [BatchedPPO, SharedPPO])
def test_imitation_fits_a_known_rule_and_keeps_to_each_agents_actions(learner_cls):
    rng = np.random.default_rng(0)
    cfg = PPOConfig(n_steps=64, n_envs=1, batch_size=64, hidden=(32, 32), learning_rate=1e-3)
    learner = learner_cls(["a", "b", "c"], 6, 4, cfg, seed=0, action_counts=COUNTS)
    train, test = rng.random((3, 600, 6)), rng.random((3, 400, 6))

    def likeliest():
        return learner.forward(learner._input(test))[0].argmax(dim=-1).numpy()

    before = (likeliest() == _rule(test)).mean()
    fit = learner.imitate(train, _rule(train), updates=1000, seed=1)
    assert fit["agreement"] > 0.95 and fit["loss"] < 0.3, fit
    chosen = likeliest()
    assert (chosen == _rule(test)).mean() > 0.9 > before + 0.3  # the rule, on observations it never saw
    assert all((chosen[k] < c).all() for k, c in enumerate(COUNTS))
    values = learner.values(test)
    assert np.allclose(values, learner_cls(["a", "b", "c"], 6, 4, cfg, seed=0, action_counts=COUNTS).values(test))


@pytest.mark.parametrize("learner_cls", [BatchedPPO, SharedPPO])
def test_imitation_with_returns_fits_the_critics_too(learner_cls):
    """Given the rule's returns (here a known function of the observation), the critics learn
    them: on observations they never saw, most of the returns' variance is explained."""
    rng = np.random.default_rng(0)
    cfg = PPOConfig(n_steps=64, n_envs=1, batch_size=64, hidden=(32, 32), learning_rate=1e-3)
    learner = learner_cls(["a", "b", "c"], 6, 4, cfg, seed=0, action_counts=COUNTS)
    train, test = rng.random((3, 600, 6)), rng.random((3, 400, 6))

    def returns(x):
        return x[..., 0] - 2 * x[..., 3]

    fit = learner.imitate(train, _rule(train), updates=1000, seed=1, returns=returns(train))
    explained = 1 - np.var(learner.values(test) - returns(test)) / np.var(returns(test))
    assert explained > 0.9 and fit["value_loss"] < 0.05 and fit["agreement"] > 0.95, (explained, fit)


def test_the_demonstrations_returns_are_discounted_within_episodes_in_the_reward_scales_units():
    """By hand: two agents, an episode of three decisions, then one of two; gamma 0.5. Unscaled,
    the returns are the discounted sums to each episode's end; scaled, they are the same sums of
    the rewards the learner's reward scale gives, whose statistics it keeps (and a fresh
    running return)."""
    from ials_zoo.baselines.imitation import scaled_returns
    from ials_zoo.learners.batched_ppo import RewardScale

    rewards = np.array([[1.0, 2.0, 4.0, 8.0, 16.0], [0.0, -1.0, 0.0, -2.0, 0.0]])
    ends = np.array([False, False, True, False, True])
    hand = np.array([[1 + 0.5 * 2 + 0.25 * 4, 2 + 0.5 * 4, 4, 8 + 0.5 * 16, 16],
                     [-0.5, -1, 0, -2, 0]])
    cfg = PPOConfig(n_steps=8, n_envs=2, gamma=0.5, normalize_reward=False)
    assert np.allclose(scaled_returns(BatchedPPO(["a", "b"], 3, 2, cfg), rewards, ends), hand)
    learner = BatchedPPO(["a", "b"], 3, 2, PPOConfig(n_steps=8, n_envs=2, gamma=0.5, normalize_reward=True))
    reference = RewardScale(2, 1, 0.5)
    scaled = np.stack([reference(rewards[:, t:t + 1], bool(ends[t]))[:, 0] for t in range(5)], axis=1)
    got = scaled_returns(learner, rewards, ends)
    assert np.allclose(got[:, 2], scaled[:, 2]) and np.allclose(got[:, 0], scaled[:, 0] + 0.5 * got[:, 1])
    assert not np.allclose(got, hand)  # the scale was applied
    assert np.allclose(learner.reward_scale.var, reference.var) and learner.reward_scale.returns.shape == (2, 2)
    assert not learner.reward_scale.returns.any()


def test_demonstrations_pair_each_observation_with_the_rules_choice_at_it():
    """Greedy on cologne3 with the ``wave`` observation (its own count, over 28, then the
    current green): at every recorded decision greedy's choice is the argmax of the light's
    greens' waves in the observation recorded with it."""
    from ials_zoo.baselines.imitation import rule_demonstrations
    from ials_zoo.core.domains import get_domain
    from ials_zoo.core.spaces import joint_sizes

    domain = get_domain("sumo_net_v0")
    options = {"net": "cologne3", "observation": "wave", "max_cycles": 40, "fresh_process": False}
    agents = domain.agents(**options)
    sizes = joint_sizes(domain, agents, options)
    obs, actions, rewards, ends = rule_demonstrations(domain, domain.rules["greedy"], agents, options, 1, 0, sizes.obs_size)
    assert obs.shape == (len(agents), 40, sizes.obs_size) and actions.shape == (len(agents), 40)
    for k, n in enumerate(sizes.action_counts):
        assert (actions[k] == np.argmax(obs[k, :, :n], axis=-1)).all()
        assert len(set(actions[k])) > 1  # it switched: the pairing is tested, not a constant
