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
    obs, actions = rule_demonstrations(domain, domain.rules["greedy"], agents, options, 1, 0, sizes.obs_size)
    assert obs.shape == (len(agents), 40, sizes.obs_size) and actions.shape == (len(agents), 40)
    for k, n in enumerate(sizes.action_counts):
        assert (actions[k] == np.argmax(obs[k, :, :n], axis=-1)).all()
        assert len(set(actions[k])) > 1  # it switched: the pairing is tested, not a constant
