"""Policies are weights plus JSON: loading one never runs code, and scores are exact."""

import contextlib
import io
import json
import os
import pickle
import zipfile

import numpy as np
import pytest
import torch

from ials_zoo.cli import main
from ials_zoo.evaluation import evaluate, evaluate_joint, load_policy
from ials_zoo.policy import (
    PolicyFileError,
    PolicyNetwork,
    load_policy_file,
    policy_from_sb3_zip,
    save_policy,
)

ENV, AGENT = "warehouse_v0", "robot_20"


class Boom:
    """Unpickling this runs a command that leaves a file behind."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def random_net(agents=(AGENT,), obs=37, actions=4, hidden=(8,), stack=1, seed=0, meta=None):
    rng = np.random.default_rng(seed)
    sizes = [obs * stack, *hidden, actions]
    layers = [(rng.normal(size=(len(agents), a, b)).astype(np.float32), rng.normal(size=(len(agents), b)).astype(np.float32))
              for a, b in zip(sizes[:-1], sizes[1:])]
    return PolicyNetwork(agents, obs, actions, layers, "tanh", stack, meta or {"env_id": ENV})


def test_roundtrip_and_exact_scores(tmp_path):
    net = random_net()
    path = save_policy(net, tmp_path / "p.safetensors")
    again = load_policy_file(path)
    x = np.random.default_rng(1).random((1, 5, 37))
    np.testing.assert_array_equal(net.probs(x), again.probs(x))
    a = evaluate(ENV, AGENT, str(path), episodes=3)
    b = evaluate(ENV, AGENT, str(path), episodes=3)
    assert a.returns == b.returns and a.policy_sha256 and a.policy_kind == "model"
    assert [p.name for p in tmp_path.iterdir()] == ["p.safetensors"]


def test_sb3_zip_is_read_without_unpickling(tmp_path):
    """A zip whose JSON 'data' holds a crafted pickle under ':serialized:' is read: the weights
    come from policy.pth (weights only), the pickle is never touched."""
    from stable_baselines3 import PPO

    from ials_zoo.influence.ials import make_ials_vec_env

    venv = make_ials_vec_env(ENV, AGENT, n_envs=2, predictor="uniform", seed=0)
    model = PPO("MlpPolicy", venv, n_steps=8, batch_size=16, device="cpu", policy_kwargs={"net_arch": [16]})
    path = tmp_path / "model.zip"
    model.save(path)
    marker = tmp_path / "pwned"
    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    data = json.loads(members["data"])
    import base64

    data["policy_class"][":serialized:"] = base64.b64encode(pickle.dumps(Boom(marker))).decode()
    members["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(path, "w") as z:
        for n, b in members.items():
            z.writestr(n, b)
    (tmp_path / "model.meta.json").write_text(json.dumps({"env_id": ENV, "agent": AGENT, "frame_stack": 1,
                                                         "sb3_class": "PPO"}))
    net = policy_from_sb3_zip(path, AGENT, 37)
    x = (np.random.default_rng(0).random((4, 37)) < 0.3).astype(np.float32)
    with torch.no_grad():
        ref = model.policy.get_distribution(torch.as_tensor(x)).distribution.probs.numpy()
    np.testing.assert_allclose(net.probs(x[None])[0], ref, atol=1e-6)
    evaluate(ENV, AGENT, str(path), episodes=1)
    assert main(["leaderboard", "convert", str(path), "--out", str(tmp_path / "c.safetensors")]) == 0
    assert not marker.exists()
    # SB3's own loader would have run it: the attack is real
    with contextlib.suppress(Exception):
        PPO.load(path)
    assert marker.exists()


def test_malicious_policy_pth_is_refused(tmp_path):
    marker = tmp_path / "pwned"
    path = tmp_path / "model.zip"
    buf = io.BytesIO()
    torch.save({"x": Boom(marker)}, buf)
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("data", "{}")
        z.writestr("policy.pth", buf.getvalue())
    with pytest.raises(PolicyFileError, match="more than weights"):
        policy_from_sb3_zip(path, AGENT, 37)
    assert not marker.exists()


@pytest.mark.parametrize("content", [b"", b"not a policy", pickle.dumps({"a": 1}), b"\x08\x00\x00\x00\x00\x00\x00\x00{}"])
def test_foreign_or_corrupt_policy_files_are_named(tmp_path, content):
    path = tmp_path / "bad.safetensors"
    path.write_bytes(content)
    with pytest.raises(PolicyFileError, match="bad.safetensors"):
        load_policy_file(path)


def test_policy_agent_and_frame_stack_must_match(tmp_path, capsys):
    path = save_policy(random_net(), tmp_path / "p.safetensors")
    with pytest.raises(ValueError, match="trained for robot_20, not 'robot_21'"):
        evaluate(ENV, "robot_21", str(path), episodes=1)
    with pytest.raises(ValueError, match="contradicts the model's"):
        load_policy(str(path), ENV, AGENT, frame_stack=8)
    with pytest.raises(ValueError, match="frame_stack must be >= 1"):
        load_policy("random", frame_stack=0)
    # the command line refuses it too
    assert main(["evaluate", "--policy", str(path), "--agent", "robot_21", "--no-progress"]) == 2
    assert "not 'robot_21'" in capsys.readouterr().err
    assert main(["evaluate", "--env", ENV, "--policy", "random", "--frame-stack", "0", "--no-progress"]) == 2


def test_joint_policy_scores_every_agent(tmp_path):
    agents = [f"robot_{i}" for i in range(4)]
    net = random_net(agents, meta={"env_id": ENV})
    path = save_policy(net, tmp_path / "joint.safetensors")
    res = evaluate_joint(ENV, str(path), episodes=2, robots=(2, 2))
    assert res.agent is None and res.agents == agents
    per = np.array([res.per_agent_returns[a] for a in agents])
    np.testing.assert_allclose(res.returns, per.mean(axis=0))
    assert evaluate_joint(ENV, str(path), episodes=2, robots=(2, 2)).returns == res.returns
    # one agent of a joint file is the same weights as the single-agent policy
    single = evaluate(ENV, "robot_1", str(path), episodes=1, robots=(2, 2))
    assert single.policy_sha256 == res.policy_sha256


def test_a_recurrent_policy_file_acts_as_the_learner_that_wrote_it(tmp_path):
    """A batched PPO learner with a GRU over 8 frames: its exported actor (saved, loaded,
    subset, numpy float64) gives the learner's own logits; the GRU's shapes are checked."""
    from ials_zoo.baselines.multiagent import joint_policy
    from ials_zoo.learners.batched_ppo import BatchedPPO, PPOConfig

    agents = ["robot_0", "robot_1", "robot_2"]
    cfg = PPOConfig(n_envs=2, hidden=(16,), recurrent_hidden=12, frames=8)
    learner = BatchedPPO(agents, 37 * 8, 4, cfg, seed=3)
    with torch.no_grad():  # weights away from their initial zeros biases
        for p in learner.params.values():
            p.add_(torch.randn_like(p) * 0.1 * (p != 0))
    x = np.random.default_rng(0).integers(0, 2, (3, 5, 37 * 8)).astype(np.float32)
    with torch.no_grad():
        want = learner.forward(learner._input(x))[0].numpy()
    net = joint_policy(agents, learner.actor_layers(), 37, 4, 8, {"env_id": ENV})
    assert net.recurrent_hidden == 12 and net.hidden == [16]
    path = save_policy(net, tmp_path / "gru.safetensors")
    again = load_policy_file(path)
    np.testing.assert_allclose(again.logits(x), want, atol=1e-5)
    np.testing.assert_allclose(again.subset(["robot_2"]).logits(x[2:]), want[2:], atol=1e-5)
    assert "GRU 12" in repr(again)
    # the file's header and its tensors must agree
    with pytest.raises(PolicyFileError, match="do not fit"):
        PolicyNetwork(agents, 36, 4, net.layers, "tanh", 8, recurrent=net.recurrent)
    res = evaluate_joint(ENV, str(path), episodes=1, robots=(3, 1))
    assert res.agents == agents and np.isfinite(res.returns).all()
