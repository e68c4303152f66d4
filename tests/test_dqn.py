"""The batched independent DQN (RESCO's IDQN) against references: its targets and one update
against a hand computation, a chain MDP whose optimal values are known, masks, exploration's
schedule and an exact resume."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from ials_zoo.core.streams import derived_seed
from ials_zoo.errors import BadInput
from ials_zoo.learners.batched_dqn import BatchedDQN, DQNConfig, DQNTrainer, SharedDQN


class Chain:
    """A multi-agent vector env of independent chains (each agent its own): states 0..S-1 seen
    one-hot; action 1 moves right, 0 left; action 1 in the last state pays 1 and stays. Every
    episode ends by time limit after ``horizon`` steps."""

    def __init__(self, agents=("a", "b"), n_envs=1, states=4, horizon=12):
        self.agents, self.n_envs, self.states, self.horizon = list(agents), n_envs, states, horizon

    def _obs(self):
        return np.eye(self.states, dtype=np.float32)[self.s]

    def reset(self, seed=None):
        rng = np.random.default_rng(seed)
        self.s, self.t = rng.integers(self.states, size=(len(self.agents), self.n_envs)), 0
        return self._obs()

    def step(self, actions):
        actions = np.asarray(actions)
        last = self.states - 1
        reward = ((self.s == last) & (actions == 1)).astype(np.float32)
        self.s = np.clip(self.s + np.where(actions == 1, 1, -1), 0, last)
        self.t += 1
        return self._obs(), reward, self.t >= self.horizon


def chain_optimum(states: int, gamma: float) -> np.ndarray:
    """Q*(s, a) of :class:`Chain` for the infinite horizon (a time limit bootstraps)."""
    v_last = 1.0 / (1.0 - gamma)
    v = np.array([gamma ** (states - 1 - s) * v_last for s in range(states)])
    q = np.zeros((states, 2))
    for s in range(states):
        q[s, 0] = gamma * v[max(s - 1, 0)]
        q[s, 1] = (1.0 + gamma * v_last) if s == states - 1 else gamma * v[s + 1]
    return q


def test_the_td_targets_and_one_update_are_the_hand_computation():
    """A linear Q (no hidden layer): the targets ``r + gamma (1 - terminal) max_a' Q_target``
    over the agent's own actions only, and one Adam step of the mean Huber loss on the
    minibatch the update draws, computed here by hand."""
    cfg = DQNConfig(batch_size=4, learning_starts=4, hidden=(), gamma=0.9, learning_rate=0.01, buffer_size=8)
    learner = BatchedDQN(["a", "b"], 3, 3, cfg, seed=5, total_steps=100, action_counts=[3, 2])
    rng = np.random.default_rng(0)
    for _ in range(6):
        x, x2 = rng.random((2, 1, 3), dtype=np.float32), rng.random((2, 1, 3), dtype=np.float32)
        learner.buffers.add(x[:, 0], rng.integers(2, size=2), 3 * rng.standard_normal(2), x2[:, 0], rng.random() < 0.3)
    W = learner.params["0.weight"].detach().numpy().astype(np.float64)
    b = learner.params["0.bias"].detach().numpy().astype(np.float64)
    x, a, r, x2, term = learner.buffers.sample(np.random.default_rng(derived_seed(5, "dqn-update", 0)), 4)
    q_next = np.einsum("abi,aio->abo", x2, W) + b[:, None, :]
    q_next[1, :, 2] = -np.inf  # agent b has 2 actions: its third is never bootstrapped from
    y = r + 0.9 * (1 - term) * q_next.max(-1)
    got = learner.td_targets(*(torch.from_numpy(v) for v in (r, x2, term))).numpy()
    assert np.allclose(got, y, atol=1e-5)
    q = np.take_along_axis(np.einsum("abi,aio->abo", x, W) + b[:, None, :], a[..., None], -1)[..., 0]
    d = np.clip(q - y, -1.0, 1.0) / 4  # Huber's derivative, averaged over the minibatch
    gW = np.zeros_like(W)
    gb = np.zeros_like(b)
    for i in range(2):
        for k in range(4):
            gW[i, :, a[i, k]] += d[i, k] * x[i, k]
            gb[i, a[i, k]] += d[i, k]
    huber = np.where(np.abs(q - y) < 1, 0.5 * (q - y) ** 2, np.abs(q - y) - 0.5)
    assert (np.abs(q - y) > 1).any() and (np.abs(q - y) < 1).any()  # both of Huber's pieces
    stats = learner.update()
    assert np.isclose(stats["loss"], huber.mean(-1).mean(), rtol=1e-5)
    for got, start, g in ((learner.params["0.weight"], W, gW), (learner.params["0.bias"], b, gb)):
        step = 0.01 * g / (np.abs(g) + 1e-8)  # Adam's first step
        assert np.allclose(got.detach().numpy(), start - step, atol=1e-6)


def _learnt_chain(kind, steps: int, buffer_size: int):
    """A learner of ``kind`` trained ``steps`` on two agents' chains; its Q of every state,
    checked against Q* (within 10%)."""
    torch.manual_seed(0)
    cfg = DQNConfig(hidden=(32,), gamma=0.8, learning_rate=3e-3, target_update=100, buffer_size=buffer_size,
                    eps_fraction=0.5, eps_end=0.1)
    env = Chain(n_envs=2)
    learner = kind(env.agents, 4, 2, cfg, seed=1, total_steps=steps)
    trainer = DQNTrainer(learner, env, seed=1)
    while learner.steps < steps:
        trainer.step()
    with torch.no_grad():
        q = learner.q_values(torch.eye(4).expand(2, 4, 4).contiguous()).numpy()
    want = chain_optimum(4, 0.8)
    assert np.abs(q - want).max() < 0.1 * want.max(), (q, want)
    return learner, q, cfg


def test_the_learner_solves_a_chain_whose_optimal_values_are_known():
    """Both agents learn Q* of their chain within 10% and act optimally (always right)."""
    learner, _, _ = _learnt_chain(BatchedDQN, 8000, 2000)
    assert (learner.greedy(np.eye(4, dtype=np.float32)[None].repeat(2, 0)) == 1).all()


def test_an_agent_never_chooses_nor_bootstraps_from_an_action_it_lacks():
    cfg = DQNConfig(hidden=(8,))
    learner = BatchedDQN(["a", "b"], 3, 4, cfg, seed=2, total_steps=10, action_counts=[4, 2])
    x = np.random.default_rng(0).random((2, 500, 3), dtype=np.float32)
    for eps_steps in (0, 10):  # exploring (epsilon 1) and greedy (epsilon 0)
        learner.steps = eps_steps
        acts = learner.act(x)
        assert acts[1].max() <= 1 and acts[0].max() <= 3
    learner.steps = 0
    assert set(np.unique(learner.act(x)[0])) == {0, 1, 2, 3}  # exploring reaches every action it has


def test_exploration_falls_linearly_over_its_fraction_of_the_run():
    learner = BatchedDQN(["a"], 2, 2, DQNConfig(hidden=(4,), eps_fraction=0.8), total_steps=1000)
    assert [learner.epsilon(t) for t in (0, 400, 800, 2000)] == [1.0, 0.5, 0.0, 0.0]


def test_the_target_network_follows_every_target_update_transitions():
    cfg = DQNConfig(hidden=(4,), batch_size=2, learning_starts=2, target_update=5, learning_rate=0.1)
    env = Chain(agents=("a",), n_envs=1)
    learner = BatchedDQN(env.agents, 4, 2, cfg, seed=0, total_steps=100)
    trainer = DQNTrainer(learner, env, seed=0)
    first = learner.target["0.weight"].clone()
    for _ in range(4):
        trainer.step()
    assert torch.equal(learner.target["0.weight"], first)  # trained, not yet synced
    assert not torch.equal(learner.params["0.weight"], first)
    trainer.step()
    assert torch.equal(learner.target["0.weight"], learner.params["0.weight"])


@pytest.mark.parametrize("kind", [BatchedDQN, SharedDQN])
def test_a_resumed_learner_continues_bit_for_bit(kind):
    cfg = DQNConfig(hidden=(16,), batch_size=8, learning_starts=8, target_update=20, buffer_size=50)

    def fresh():
        env = Chain(n_envs=2, horizon=7)
        learner = kind(env.agents, 4, 2, cfg, seed=3, total_steps=400)
        return learner, DQNTrainer(learner, env, seed=3)

    whole, trainer = fresh()
    for _ in range(150):
        trainer.step()
    cut, cut_trainer = fresh()
    for _ in range(61):
        cut_trainer.step()
    state, episodes = cut.state_dict(), cut_trainer.state()
    resumed, resumed_trainer = fresh()
    resumed.load_state_dict(state)
    resumed_trainer.restore(episodes)
    for _ in range(89):
        resumed_trainer.step()
    for k in whole.params:
        assert torch.equal(whole.params[k], resumed.params[k]), k
        assert torch.equal(whole.target[k], resumed.target[k]), k
    assert whole.steps == resumed.steps and whole.updates == resumed.updates


@pytest.mark.parametrize("field, value, flag", [("batch_size", 0, "--batch-size"), ("eps_end", 1.5, "--eps-end"),
                                                ("buffer_size", 10, "--buffer-size"),
                                                ("eps_fraction", 0.0, "--eps-fraction"),
                                                ("learning_starts", 1, "--learning-starts")])
def test_settings_no_dqn_can_run_with_are_refused_by_their_flag(field, value, flag):
    with pytest.raises(BadInput, match=flag):
        BatchedDQN(["a"], 2, 2, DQNConfig(**{field: value}), total_steps=10)


def test_a_recorded_idqn_command_is_read_back_and_costed_by_its_updates():
    """``verify --retrain`` reads an IDQN command and estimates its minibatch updates: a
    minibatch of 10**6 makes them the setting that costs most."""
    from ials_zoo.baselines import idqn
    from ials_zoo.baselines.retrain import parse_command, run_parts

    command = ("ials-zoo train idqn --env warehouse_v0 --agents robot_0,robot_1 --env-options '{\"robots\": [2, 2]}' "
               "--total-timesteps 1000")
    module, args = parse_command(command, 3)
    assert module is idqn and args.seed == 3 and args.batch_size == 32
    data = {"env_id": "warehouse_v0", "agents": ["robot_0", "robot_1"]}
    assert dict(run_parts(data, args))["--train-every/--batch-size"] > 0
    _, big = parse_command(command + " --batch-size 1000000 --buffer-size 2000000 --learning-starts 1000000", 0)
    parts = run_parts(data, big)
    assert max(parts, key=lambda p: p[1])[0] == "--train-every/--batch-size"


def test_the_policy_file_acts_as_the_learner_greedily_sampled_and_deterministic(tmp_path):
    """What IDQN writes (Q / GREEDY_TEMPERATURE as logits, ReLU, masks of lights with fewer
    actions) picks each agent's argmax of Q, sampled as well as deterministic, after a round
    trip through the file."""
    from ials_zoo.baselines.idqn import DQNCopiesLearner
    from ials_zoo.policy import load_policy_file, save_policy

    class Sizes:
        obs_size, n_actions, action_counts = 6, 4, [4, 2, 3]

    adapter = DQNCopiesLearner("warehouse_v0", ["a", "b", "c"], {}, 1, 0, DQNConfig(hidden=(16, 16)), 1, 7, 100, Sizes)
    with torch.no_grad():  # weights far from the initial ones, so that Q-values differ by little and by much
        for v in adapter.learner.params.values():
            v.mul_(3.0)
    net = load_policy_file(save_policy(adapter.policy({"algorithm": "idqn"}), tmp_path / "p.safetensors"))
    x = np.random.default_rng(0).random((3, 500, 6), dtype=np.float32)
    greedy = adapter.learner.greedy(x)
    assert (net.act(x, deterministic=True) == greedy).all()
    assert (net.act(x, np.random.default_rng(1)) == greedy).mean() > 0.99
    assert greedy[1].max() <= 1 and greedy[2].max() <= 2


def test_the_shared_dqns_targets_and_update_are_the_hand_computation():
    """One linear Q for every agent, one minibatch from the pooled buffer: each row bootstraps
    over its own agent's actions only, and one Adam step of the mean Huber loss over the rows."""
    cfg = DQNConfig(batch_size=6, learning_starts=6, hidden=(), gamma=0.9, learning_rate=0.01, buffer_size=7)
    learner = SharedDQN(["a", "b"], 3, 3, cfg, seed=5, total_steps=100, action_counts=[3, 2])
    rng = np.random.default_rng(0)
    for _ in range(5):  # 10 transitions into 7 rows: the buffer wraps
        learner.buffers.add(rng.random((2, 3), dtype=np.float32), rng.integers(2, size=2),
                            3 * rng.standard_normal(2), rng.random((2, 3), dtype=np.float32), rng.random() < 0.3)
    assert learner.buffers.size == 7 and learner.buffers.pos == 3
    assert list(learner.buffers.agent) == [1, 0, 1, 1, 0, 1, 0]  # rows 6, 0 and 1, 2 rewritten by the last two steps
    W = learner.params["0.weight"].detach().numpy()[0].astype(np.float64)
    b = learner.params["0.bias"].detach().numpy()[0].astype(np.float64)
    x, a, r, x2, term, who = learner.buffers.sample(np.random.default_rng(derived_seed(5, "dqn-update", 0)), 6)
    x, a, r, x2, term = (v[0] for v in (x, a, r, x2, term))
    assert set(who) == {0, 1}
    q_next = x2 @ W + b
    q_next[who == 1, 2] = -np.inf  # agent b has 2 actions
    y = r + 0.9 * (1 - term) * q_next.max(-1)
    q = (x @ W + b)[np.arange(6), a]
    d = np.clip(q - y, -1.0, 1.0) / 6
    gW, gb = np.zeros_like(W), np.zeros_like(b)
    for k in range(6):
        gW[:, a[k]] += d[k] * x[k]
        gb[a[k]] += d[k]
    huber = np.where(np.abs(q - y) < 1, 0.5 * (q - y) ** 2, np.abs(q - y) - 0.5)
    stats = learner.update()
    assert np.isclose(stats["loss"], huber.mean(), rtol=1e-5)
    for got, start, g in ((learner.params["0.weight"], W, gW), (learner.params["0.bias"], b, gb)):
        step = 0.01 * g / (np.abs(g) + 1e-8)
        assert np.allclose(got.detach().numpy()[0], start - step, atol=1e-6)


def test_the_shared_dqn_learns_one_q_for_every_agent_from_all_their_transitions():
    """Two agents on the same chain share one network: it reaches Q* within 10% for both,
    and gives both the same Q on the same input; an agent's missing action stays at -inf."""
    _, q, cfg = _learnt_chain(SharedDQN, 5000, 4000)
    assert np.array_equal(q[0], q[1])
    masked = SharedDQN(["a", "b"], 4, 3, cfg, seed=1, total_steps=10, action_counts=[3, 2])
    acts = masked.act(np.random.default_rng(0).random((2, 400, 4), dtype=np.float32))
    assert acts[1].max() == 1 and acts[0].max() == 2
    layers = masked.q_layers()
    assert layers[0][0].shape == (2, 4, 32) and np.array_equal(layers[0][0][0], layers[0][0][1])
    with pytest.raises(BadInput, match="--buffer-size"):
        SharedDQN(["a", "b", "c"], 2, 2, DQNConfig(hidden=(4,), buffer_size=2, batch_size=2, learning_starts=2))
