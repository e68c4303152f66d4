"""sumo_net_v0 on the board and in the learners: a track per map ranked by RESCO's delay,
policies for agents with spaces of their own (padded observations, masked actions), re-measured
exactly."""

import json

import numpy as np
import pytest

from ials_zoo import leaderboard as lb
from ials_zoo.core.domains import get_domain
from ials_zoo.core.spaces import JointSizes, joint_sizes, stack_observations
from ials_zoo.errors import BadInput
from ials_zoo.evaluation import eval_seeds, evaluate, evaluate_joint
from ials_zoo.learners.batched_ppo import BatchedPPO, PPOConfig
from ials_zoo.policy import PolicyFileError, PolicyNetwork, load_policy_file, save_policy

ENV = "sumo_net_v0"


def _masked_policy(agents, sizes: JointSizes, seed: int) -> PolicyNetwork:
    rng = np.random.default_rng(seed)
    A = len(agents)
    layers = [(rng.normal(size=(A, sizes.obs_size, 16)).astype(np.float32), np.zeros((A, 16), np.float32)),
              (rng.normal(size=(A, 16, sizes.n_actions)).astype(np.float32), np.zeros((A, sizes.n_actions), np.float32))]
    return PolicyNetwork(agents, sizes.obs_size, sizes.n_actions, layers, metadata={"env_id": ENV},
                         action_counts=sizes.action_counts)


def test_cologne8_agents_are_padded_and_masked():
    domain = get_domain(ENV)
    agents = domain.agents(net="cologne8")
    sizes = joint_sizes(domain, agents, {"net": "cologne8"})
    assert sizes.obs_size == 30 and sizes.n_actions == 4 and sorted(sizes.action_counts) == [2, 2, 3, 3, 3, 4, 4, 4]
    x = stack_observations({"a": np.ones(2), "b": np.ones(3)}, ["a", "b"], 4)
    np.testing.assert_array_equal(x, [[1, 1, 0, 0], [1, 1, 1, 0]])


def test_a_masked_policy_file_never_picks_a_missing_action_and_round_trips(tmp_path):
    sizes = JointSizes(6, 4, (2, 4, 3))
    net = _masked_policy(["a", "b", "c"], sizes, 0)
    loaded = load_policy_file(save_policy(net, tmp_path / "p.safetensors"))
    assert loaded.action_counts == (2, 4, 3) and loaded.header()["format_version"] == 2
    x = np.random.default_rng(1).normal(size=(3, 500, 6))
    p = loaded.probs(x)
    assert (p[0, :, 2:] == 0).all() and (p[2, :, 3:] == 0).all() and np.allclose(p.sum(-1), 1)
    acts = loaded.act(x, np.random.default_rng(2))
    assert acts[0].max() <= 1 and acts[2].max() <= 2 and acts[1].max() == 3
    assert loaded.subset(["c", "a"]).action_counts == (3, 2)
    # a version-2 header without its counts, or counts out of range, is refused
    import json as _json

    from safetensors import safe_open
    from safetensors.numpy import save

    path = tmp_path / "p.safetensors"
    with safe_open(str(path), framework="np") as f:
        header, tensors = _json.loads(f.metadata()["ials_zoo.policy"]), {k: f.get_tensor(k) for k in f.keys()}
    del header["action_counts"]
    (tmp_path / "q.safetensors").write_bytes(save(tensors, metadata={"ials_zoo.policy": _json.dumps(header)}))
    with pytest.raises(PolicyFileError, match="reads version 1, and 2 with action_counts"):
        load_policy_file(tmp_path / "q.safetensors")
    with pytest.raises(PolicyFileError, match="action_counts"):
        PolicyNetwork(["a"], 6, 4, [(np.zeros((1, 6, 4), np.float32), np.zeros((1, 4), np.float32))],
                      action_counts=[5])


def test_batched_ppo_masks_and_learns_only_the_actions_an_agent_has():
    cfg = PPOConfig(n_steps=32, n_envs=2, batch_size=32, n_epochs=2)
    ppo = BatchedPPO(["a", "b"], 6, 4, cfg, seed=0, action_counts=[2, 4])
    obs = np.random.default_rng(0).normal(size=(2, 2, 6)).astype(np.float32)
    seen = set()
    for _ in range(200):
        actions, _, logp = ppo.act(obs)
        seen |= {(0, int(a)) for a in actions[0]} | {(1, int(a)) for a in actions[1]}
        assert np.isfinite(logp).all()
    assert {a for k, a in seen if k == 0} == {0, 1} and {a for k, a in seen if k == 1} == {0, 1, 2, 3}
    import torch

    probs = torch.softmax(ppo.forward(ppo._input(obs))[0], dim=-1).detach().numpy()
    assert (probs[0, :, 2:] == 0).all() and (probs[1] > 0).all()  # the learner's own distribution is masked


def test_the_protocol_of_a_map_is_official_with_every_light_and_only_the_net_option():
    agents = get_domain(ENV).agents(net="cologne8")
    assert lb.protocol_of("multi-agent", ENV, agents, eval_seeds(), {"net": "cologne8"}) == "official"
    assert lb.protocol_of("multi-agent", ENV, agents, eval_seeds(), {}) == "variant"  # the map is named, not defaulted
    assert lb.protocol_of("multi-agent", ENV, agents[:3], eval_seeds(), {"net": "cologne8"}) == "variant"
    assert lb.protocol_of("multi-agent", ENV, agents, eval_seeds(), {"net": "cologne8", "max_cycles": 9}) == "variant"


def _entry(tmp_path, policy: PolicyNetwork, name: str) -> dict:
    path = save_policy(policy, tmp_path / f"{name}.safetensors")
    ev = evaluate_joint(ENV, str(path), episodes=2, net="cologne8", max_cycles=30)
    return lb.make_result([ev], algorithm=name, training_seeds=[0], training={
        "simulator": "gs", "aip": None, "seeds": [0], "env_steps": 1000, "wall_clock_seconds": 1.0,
        "aip_seconds": 0.0, "hyperparameters": {}})


def test_a_map_is_a_track_ranked_by_delay_and_its_entries_re_measure_exactly(tmp_path):
    board = tmp_path / "board"
    (board / "results").mkdir(parents=True)
    domain = get_domain(ENV)
    agents = domain.agents(net="cologne8")
    sizes = joint_sizes(domain, agents, {"net": "cologne8"})
    entries = [_entry(tmp_path, _masked_policy(agents, sizes, s), f"net{s}") for s in (0, 1)]
    for d in entries:
        assert d["metrics"]["delay"]["mean"] > 0
        (tmp_path / f"{d['algorithm']}.json").write_text(json.dumps(d))
        lb.submit(tmp_path / f"{d['algorithm']}.json", board)
    best, worst = sorted(entries, key=lambda d: d["metrics"]["delay"]["mean"])
    table = lb.show(board)
    assert "net=cologne8: 8 agents" in table and "delay (lower is better)" in table
    assert table.index(best["algorithm"] + " ") < table.index(worst["algorithm"] + " ")
    readme = lb.render(board).read_text()
    assert "delay [95% CI] (lower is better)" in readme
    for p in (board / "results").glob("*.json"):
        assert lb.verify(p, directory=board)[0]["ok"]


def test_the_rules_are_reference_entries_of_each_map_re_measured_exactly(tmp_path):
    """``rule:NAME`` entries: the lights driven as the rule drives them (greedy's delay is the
    study's controller episode), each its own entry on the map's track, re-measured on submit;
    a rule's entry that claims training or another rule's name is refused."""
    from ials_zoo.sumo_net.controllers import run_episode

    board = tmp_path / "board"
    (board / "results").mkdir(parents=True)
    entries = {}
    for rule in ("greedy", "fixed"):
        ev = evaluate_joint(ENV, f"rule:{rule}", seeds=[10000], net="cologne1", max_cycles=30)
        assert ev.metrics["delay"]["mean"] == run_episode(rule, 10000, net="cologne1", max_cycles=30)["delay"]
        d = lb.make_result([ev], algorithm=rule)
        assert d["policy"] == {"name": rule, "kind": "rule", "frame_stack": 1, "deterministic": False}
        lb.validate_result(d)
        (tmp_path / f"{rule}.json").write_text(json.dumps(d))
        lb.submit(tmp_path / f"{rule}.json", board)
        entries[rule] = d
    assert entries["greedy"]["metrics"]["delay"]["mean"] < entries["fixed"]["metrics"]["delay"]["mean"]
    assert "greedy (rule)" in lb.show(board) and "fixed (rule)" in lb.show(board)
    for p in (board / "results").glob("*.json"):
        assert lb.verify(p, directory=board)[0]["ok"]
    delay = entries["greedy"]["scores"][0]["metrics"]["delay"]
    assert delay["episodes"] == [delay["mean"]] == [delay["median"]]  # every episode's delay is kept
    forged = json.loads(json.dumps(entries["greedy"]))
    forged["scores"][0]["metrics"]["delay"]["episodes"] = [delay["mean"] + 1.0]
    with pytest.raises(lb.ResultError, match="does not match its episodes"):
        lb.validate_result(forged)
    bad = dict(entries["greedy"], algorithm="fixed")
    with pytest.raises(lb.ResultError, match="training"):
        lb.validate_result(bad)
    bad = dict(entries["greedy"], policy=dict(entries["greedy"]["policy"], name="maxwave"), algorithm="maxwave")
    with pytest.raises(lb.ResultError, match="no rule 'maxwave'"):
        lb.validate_result(bad)
    with pytest.raises(BadInput, match="rule:greedy, rule:fixed|its rules: rule:fixed"):
        evaluate_joint(ENV, "rule:maxwave", episodes=1, net="cologne1")
    with pytest.raises(BadInput, match="multi-agent track"):
        evaluate(ENV, get_domain(ENV).agents(net="cologne1")[0], "rule:greedy", episodes=1, net="cologne1")


def test_a_maps_track_shows_rescos_published_figures_beside_it_never_a_variants():
    from ials_zoo.leaderboard.render import published_of

    row = {"env_id": ENV, "evaluation": {"protocol": "official", "options": {"net": "cologne8"}}}
    note, rows = published_of([row])
    assert "not re-measured" in note and "SUMO 1.9" in note
    assert ("RESCO IDQN", "22.06") in rows and ("RESCO MAXWAVE", "21.87 (21.85)") in rows
    assert published_of([dict(row, evaluation={"protocol": "variant", "options": {"net": "cologne8"}})]) == ("", [])
    assert published_of([dict(row, evaluation={"protocol": "official", "options": {"net": "grid3x3"}})]) == ("", [])


def test_mplight_shares_one_dqn_learns_from_pressure_and_is_scored_on_the_protocols_reward(tmp_path):
    """MPLight's policy reads the pressure observation its file records, and is scored, like
    every entry, on RESCO's wait_norm: its result re-evaluates exactly from the file, stays on
    the official protocol with only the map and its observation named, and never on pressure."""
    from ials_zoo.baselines import mplight

    agents = get_domain(ENV).agents(net="cologne8")
    assert lb.protocol_of("multi-agent", ENV, agents, eval_seeds(), {"net": "cologne8", "observation": "mplight"}) \
        == "official"
    assert lb.protocol_of("multi-agent", ENV, agents, eval_seeds(), {"net": "cologne8", "reward": "pressure"}) \
        == "variant"
    out = tmp_path / "run"
    result = mplight.main(mplight.Args(env_id=ENV, env_options='{"net": "cologne8", "max_cycles": 20}',
                                       total_timesteps=60, eval_every=60, eval_episodes=1, final_eval_episodes=2,
                                       out_dir=str(out), progress=False))
    options = result["evaluation"]["options"]
    assert options == {"net": "cologne8", "max_cycles": 20, "observation": "mplight"}
    assert result["training"]["hyperparameters"]["train_options"] == {"reward": "pressure"}
    adapter = mplight.idqn.DQNCopiesLearner(ENV, agents, options, 1, 0, mplight.idqn.dqn_config(mplight.Args()), 1, 0,
                                            60, joint_sizes(get_domain(ENV), agents, options),
                                            learner_cls=mplight.SharedDQN, train_options={"reward": "pressure"})
    assert adapter.options == dict(options, reward="pressure")  # the GS copies it learns on
    args = mplight.idqn.Args(env_id=ENV, train_reward="wait_scaled")
    assert mplight.idqn.train_options_of(args, get_domain(ENV), {"net": "cologne8"}) == {"reward": "wait_scaled"}
    # a run without --train-reward records what runs recorded before it existed (re-training stays bit for bit)
    from ials_zoo.baselines import ippo
    from ials_zoo.baselines.driver import _recorded

    assert "train_reward" not in _recorded(ippo.Args()) and _recorded(args)["train_reward"] == "wait_scaled"
    net = load_policy_file(out / "policy.safetensors")
    first = net.layers[0][0]
    assert all(np.array_equal(first[0], first[i]) for i in range(len(agents)))  # one network for every light
    again = evaluate_joint(ENV, str(out / "policy.safetensors"), episodes=2, **options)
    assert again.returns == result["scores"][0]["returns"]
    on_pressure = evaluate_joint(ENV, str(out / "policy.safetensors"), episodes=2, reward="pressure", **options)
    assert on_pressure.returns != again.returns


def test_ippo_trains_every_light_of_a_map_with_its_own_actions(tmp_path):
    """cologne3: lights with 3, 4 and 4 greens, observations of 19 lanes in all: the run's
    policy file masks each light's missing greens and the board re-measures it exactly."""
    from ials_zoo.baselines import ippo

    out = tmp_path / "run"
    args = ippo.Args(env_id=ENV, env_options='{"net": "cologne3", "max_cycles": 32}', total_timesteps=256,
                     samples_per_update=128, batch_size=64, n_envs=1, eval_every=256, eval_episodes=1,
                     final_eval_episodes=1, out_dir=str(out), progress=False)
    result = ippo.main(args)
    net = load_policy_file(out / "policy.safetensors")
    domain = get_domain(ENV)
    agents = domain.agents(net="cologne3")
    assert list(net.agents) == agents and net.action_counts == joint_sizes(domain, agents, {"net": "cologne3"}).action_counts
    assert sorted(net.action_counts) == [3, 4, 4]
    assert result["metrics"]["delay"]["mean"] > 0
    (tmp_path / "r.json").write_text(json.dumps(result))
    assert lb.verify(tmp_path / "r.json", policies=[out / "policy.safetensors"])[0]["ok"]
