"""PPO baselines: short real training runs on every simulator kind, truncation bootstrapping."""

import json

import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecEnvWrapper

from ials_zoo.baselines import ppo_shared, ppo_single
from ials_zoo.evaluation import eval_seeds, evaluate
from ials_zoo.influence.specs import predictor_for
from ials_zoo.leaderboard import load_result

ENV, AGENT = "warehouse_v0", "robot_20"
TINY = dict(env_id=ENV, total_timesteps=1024, n_envs=4, n_steps=64, batch_size=128, net_arch="16",
            eval_every=512, eval_episodes=2, final_eval_episodes=3, progress=False)


@pytest.fixture(scope="module")
def small_aip(tmp_path_factory):
    """A real (tiny) AIP: Algorithm 1 on the GS, then a short MLP training, saved to a file."""
    from ials_zoo.influence.dataset import collect
    from ials_zoo.influence.files import save_predictor
    from ials_zoo.influence.train import train_predictor

    data = collect(ENV, AGENT, steps=1000, progress=False)
    pred, _ = train_predictor(data, arch="mlp", epochs=1, progress=False)
    return str(save_predictor(pred, tmp_path_factory.mktemp("aip") / "aip.pt"))


def _check_run(out, simulator, result):
    from ials_zoo.baselines.runs import run_state

    assert (out / "policy.safetensors").is_file() and (out / "progress.csv").is_file()
    assert (out / "checkpoint.pt").is_file() and (out / "checkpoint.json").is_file()
    assert run_state(out) == "finished"
    import csv

    with open(out / "progress.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["steps_per_agent"]) for r in rows] == [512, 1024]  # one row per stretch between evaluations
    assert all(float(r["entropy"]) > 0 and r["policy_loss"] and r["learning_rate"] for r in rows)
    curve = json.loads((out / "curve.json").read_text())["points"]
    assert [p["env_steps"] for p in curve] == [0, 512, 1024]
    assert all(b["wall_clock_seconds"] > a["wall_clock_seconds"] for a, b in zip(curve, curve[1:]))
    data = load_result(out / "result.json")
    assert data == result
    assert data["training"]["simulator"] == simulator
    assert data["training"]["env_steps"] == 1024
    assert data["policy"]["frame_stack"] == 1  # the warehouse's learned policies read one observation
    assert data["learning_curves"][0]["points"] == curve
    assert data["evaluation"]["seeds"] == eval_seeds(3)
    # The saved policy is scored later without the training code, to the same numbers.
    again = evaluate(ENV, AGENT, str(out / "policy.safetensors"), episodes=3)
    assert again.returns == data["scores"][0]["returns"]
    assert again.policy_sha256 == data["scores"][0]["policy_sha256"]
    return data


@pytest.mark.parametrize("simulator", ["gs", "untrained-ials", "fixed:0.1"])
def test_ppo_single_short_run(tmp_path, simulator):
    out = tmp_path / "run"
    result = ppo_single.main(ppo_single.Args(simulator=simulator, out_dir=str(out), **TINY))
    data = _check_run(out, simulator, result)
    # the same policy, scored again with its most likely actions, as the multi-agent runs do
    det = json.loads((out / "result_deterministic.json").read_text())
    assert det["evaluation"]["deterministic"] is True and not data["evaluation"]["deterministic"]
    reference = evaluate(ENV, AGENT, str(out / "policy.safetensors"), episodes=TINY["final_eval_episodes"],
                         deterministic=True)
    assert det["scores"][0]["returns"] == reference.returns
    assert det["training"] == data["training"]
    if simulator == "gs":
        assert data["training"]["aip"] is None
    else:
        assert data["training"]["aip"]["collection_seconds"] == 0.0


def test_ppo_single_scales_rewards_over_every_step_and_checkpoints_the_scale(tmp_path):
    import torch

    out = tmp_path / "run"
    ppo_single.main(ppo_single.Args(simulator="untrained-ials", out_dir=str(out), normalize_reward=True,
                                    **dict(TINY, eval_every=0)))
    rms = torch.load(out / "checkpoint.pt", weights_only=True)["models"]["policy"]["reward_rms"]
    assert float(rms["count"]) == pytest.approx(1024, abs=1e-3)  # VecNormalize saw every training step
    assert float(rms["var"]) > 0
    plain = tmp_path / "plain"
    ppo_single.main(ppo_single.Args(simulator="untrained-ials", out_dir=str(plain), normalize_reward=False,
                                    **dict(TINY, eval_every=0)))
    assert "reward_rms" not in torch.load(plain / "checkpoint.pt", weights_only=True)["models"]["policy"]

def test_ppo_single_on_trained_ials_counts_aip_time(tmp_path, small_aip):
    from ials_zoo.influence.files import load_predictor

    out = tmp_path / "run"
    result = ppo_single.main(ppo_single.Args(simulator=small_aip, out_dir=str(out), **TINY))
    data = _check_run(out, "ials", result)  # a trained AIP file is labelled "ials"
    aip = data["training"]["aip"]
    assert aip["file"] == small_aip and aip["sha256"]
    meta = load_predictor(small_aip).metadata
    assert aip["collection_seconds"] == meta["dataset"]["collect_seconds"] > 0
    assert aip["training_seconds"] == meta["train_seconds"] > 0
    assert data["training"]["aip_seconds"] == pytest.approx(aip["collection_seconds"] + aip["training_seconds"])
    # the curve's wall-clock includes the AIP's collection + training time
    assert data["learning_curves"][0]["points"][0]["wall_clock_seconds"] > data["training"]["aip_seconds"]
    assert aip["sha256"] is not None and len(aip["sha256"]) == 64


def test_train_command_runs_a_baseline(tmp_path):
    from ials_zoo.cli import main

    out = tmp_path / "cli"
    rc = main(["train", "ppo_single", "--env", ENV, "--simulator", "gs", "--total-timesteps", "256",
               "--n-envs", "2", "--n-steps", "64", "--batch-size", "64", "--net-arch", "8",
               "--eval-every", "0", "--eval-episodes", "1", "--final-eval-episodes", "2",
               "--out-dir", str(out), "--no-progress"])
    assert rc == 0
    assert load_result(out / "result.json")["training"]["env_steps"] == 256
    assert main(["train", "ppo_single", "--env", ENV, "--simulator", "bogus", "--out-dir", str(out)]) == 2
    with pytest.raises(SystemExit) as done:  # which domain? (argparse's: --env is required)
        main(["train", "ppo_single", "--simulator", "gs"])
    assert done.value.code == 2


def test_a_used_out_dir_is_refused_unless_resume_or_overwrite(tmp_path, capsys):
    from ials_zoo.baselines.runs import RunFolder, run_state

    out = tmp_path / "run"
    args = dict(TINY, total_timesteps=512, eval_every=256, final_eval_episodes=2)
    first = ppo_single.main(ppo_single.Args(simulator="gs", out_dir=str(out), **args))
    with pytest.raises(ValueError, match="already holds a finished run"):
        ppo_single.main(ppo_single.Args(simulator="gs", out_dir=str(out), **args))
    with pytest.raises(ValueError, match="nothing to resume"):
        ppo_single.main(ppo_single.Args(simulator="gs", out_dir=str(out), resume=True, **args))
    again = ppo_single.main(ppo_single.Args(simulator="gs", out_dir=str(out), overwrite=True, **args))
    assert again["scores"][0]["returns"] == first["scores"][0]["returns"]  # same seed, same run
    # a run killed after a checkpoint: status says running with a dead pid -> "killed"
    status = json.loads((out / "status.json").read_text())
    status.update(state="running", pid=2**22 + 12345)
    (out / "status.json").write_text(json.dumps(status))
    (out / "result.json").unlink()
    assert run_state(out) == "killed"
    with pytest.raises(ValueError, match="already holds a killed run"):
        RunFolder(out, settings=status["settings"])
    with pytest.raises(ValueError, match="other settings"):
        ppo_single.main(ppo_single.Args(simulator="gs", out_dir=str(out), resume=True, **dict(args, seed=1)))
    resumed = ppo_single.main(ppo_single.Args(simulator="gs", out_dir=str(out), resume=True, **args))
    assert resumed["training"]["env_steps"] >= 512 and run_state(out) == "finished"
    file = tmp_path / "a_file"
    file.write_text("x")
    with pytest.raises(ValueError, match="is a file"):
        ppo_single.main(ppo_single.Args(simulator="gs", out_dir=str(file), **args))


@pytest.mark.parametrize("bad,match", [("bogus", "unknown simulator"), ("fixed:2", "fixed:P"),
                                       ("/nope/aip.pt", "not found")])
def test_bad_simulator_is_named(bad, match):
    with pytest.raises(ValueError, match=match):
        predictor_for(bad)


def test_ppo_shared_short_run(tmp_path):
    out = tmp_path / "shared"
    results = ppo_shared.main(ppo_shared.Args(
        env_id=ENV, learners="robot_20,robot_21", eval_agents="robot_20,robot_21", total_timesteps=512,
        n_steps=64, batch_size=64, net_arch="16", eval_every=256, eval_episodes=2,
        final_eval_episodes=2, out_dir=str(out), progress=False))
    assert [r["agent"] for r in results] == ["robot_20", "robot_21"]
    for r in results:
        data = load_result(out / f"result_{r['agent']}.json")
        assert data["algorithm"] == "ppo_shared"
        assert data["trained_agents"] == ["robot_20", "robot_21"]
    assert [p["env_steps"] for p in results[0]["learning_curves"][0]["points"]] == [0, 256, 512]


# --------------------------------------------------------------------------------------------
# Truncation bootstrapping: PPO must add gamma * V(terminal observation) to the reward of a
# truncated step (SB3 does it when infos carry TimeLimit.truncated + terminal_observation).


class _Recorder(VecEnvWrapper):
    def __init__(self, venv):
        super().__init__(venv)
        self.rewards, self.infos = [], []

    def reset(self):
        return self.venv.reset()

    def step_wait(self):
        obs, rew, dones, infos = self.venv.step_wait()
        self.rewards.append(np.array(rew, dtype=np.float64))
        self.infos.append([dict(i) for i in infos])
        return obs, rew, dones, infos


def _bootstrap_added(venv, n_steps=8, gamma=0.9, seed=0):
    """Run one PPO rollout; return (added reward at truncated steps, expected, at other steps)."""
    import torch

    rec = _Recorder(venv)
    model = PPO("MlpPolicy", rec, n_steps=n_steps, batch_size=n_steps, gamma=gamma, seed=seed,
                policy_kwargs={"net_arch": [8]}, device="cpu")
    _, callback = model._setup_learn(n_steps * rec.num_envs, callback=None)
    model.collect_rollouts(rec, callback, model.rollout_buffer, n_rollout_steps=n_steps)
    added = model.rollout_buffer.rewards - np.array(rec.rewards)
    trunc, expected, other = [], [], []
    for t, infos in enumerate(rec.infos):
        for i, info in enumerate(infos):
            if "terminal_observation" in info:
                with torch.no_grad():
                    v = model.policy.predict_values(torch.as_tensor(info["terminal_observation"][None]))
                trunc.append(added[t, i])
                expected.append(gamma * float(v))
            else:
                other.append(added[t, i])
    rec.close()
    return np.array(trunc), np.array(expected), np.array(other)


def test_gs_vec_env_truncation_is_bootstrapped():
    from ials_zoo.single_agent import make_gs_vec_env

    got, want, other = _bootstrap_added(make_gs_vec_env(ENV, AGENT, n_envs=2, max_cycles=5))
    assert len(got) == 2 * (8 // 5)
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-6)
    assert np.abs(want).min() > 0
    np.testing.assert_allclose(other, 0.0, atol=1e-6)


def test_ials_vec_env_truncation_is_bootstrapped():
    from ials_zoo.influence.ials import make_ials_vec_env

    venv = make_ials_vec_env(ENV, AGENT, n_envs=2, predictor="untrained", seed=0, max_cycles=5)
    got, want, other = _bootstrap_added(venv)
    assert len(got) == 2
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(other, 0.0, atol=1e-6)


def test_supersuit_adapter_truncation_is_bootstrapped():
    venv = ppo_shared.make_shared_vec_env(ENV, learners=["robot_20", "robot_21", "robot_14"],
                                          n_copies=2, seed=0, max_cycles=5)
    got, want, other = _bootstrap_added(venv)
    assert len(got) == 6  # 3 agents x 2 copies, one truncation each in 8 steps
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-6)
    assert np.abs(want).min() > 0
    np.testing.assert_allclose(other, 0.0, atol=1e-6)


@pytest.mark.filterwarnings("ignore:The `render_mode` attribute")
def test_stock_supersuit_wrapper_does_not_bootstrap():
    """The reason for the adapter: SuperSuit's own SB3 wrapper loses the truncation."""
    import supersuit as ss

    from ials_zoo.warehouse_v0 import parallel_env

    par = parallel_env(learners=["robot_20", "robot_21"], max_cycles=5)
    venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(par), 1, base_class="stable_baselines3")
    got, want, _ = _bootstrap_added(venv, seed=None)  # it cannot even be seeded
    assert len(got) == 2
    np.testing.assert_allclose(got, 0.0, atol=1e-6)
    assert np.abs(want).min() > 0


def test_training_clock_stands_still_while_paused():
    import time

    from ials_zoo.baselines.runs import Clock

    clock = Clock(offset=100.0)
    time.sleep(0.01)
    with clock.pause():
        inside = clock.seconds
        time.sleep(0.05)
        assert clock.seconds == inside
    after = clock.seconds
    assert 100.0 < inside <= after < inside + 0.04


def test_env_options_reach_training_and_evaluation(tmp_path):
    """GS/LS options (here items vanishing after 2 steps) reach training, scoring, re-scoring."""
    from ials_zoo.cli import main

    out = tmp_path / "mem"
    args = dict(TINY, total_timesteps=256, n_envs=2, eval_every=0, final_eval_episodes=2)
    result = ppo_single.main(ppo_single.Args(simulator="untrained-ials", out_dir=str(out),
                                             env_options='{"item_lifetime": 2}', **args))
    assert result["evaluation"]["options"] == {"item_lifetime": 2}
    plain = evaluate(ENV, AGENT, str(out / "policy.safetensors"), episodes=2)
    memory = evaluate(ENV, AGENT, str(out / "policy.safetensors"), episodes=2, item_lifetime=2)
    assert memory.returns == result["scores"][0]["returns"] != plain.returns
    rc = main(["evaluate", "--policy", str(out / "policy.safetensors"), "--episodes", "2",
               "--out", str(tmp_path / "r.json"), "--no-progress"])
    assert rc == 0
    assert load_result(tmp_path / "r.json")["scores"][0]["returns"] == memory.returns
    with pytest.raises(ValueError, match="JSON object"):
        ppo_single.main(ppo_single.Args(env_id=ENV, env_options="[1]", out_dir=str(out)))


def test_ppo_single_on_the_shipped_aip_charges_only_what_it_did(tmp_path):
    """--simulator ials with the shipped AIP: the run's wall-clock is its own training; the AIP's
    recorded cost is kept in training.aip, not charged, and its file is named portably."""
    out = tmp_path / "run"
    result = ppo_single.main(ppo_single.Args(simulator="ials", out_dir=str(out), **TINY))
    aip = result["training"]["aip"]
    assert aip["charged"] is False and aip["collection_seconds"] + aip["training_seconds"] > 0
    assert result["training"]["aip_seconds"] == 0.0
    assert aip["file"].startswith("ials_zoo/influence/pretrained/") and not aip["file"].startswith("/")


def test_the_aip_record_charges_only_an_aip_this_run_made_and_names_only_a_shipped_file(tmp_path):
    """The record reads where the predictor came from (``source``): a shipped file is named and not
    charged, a cached one (outside the package) is neither, one made in this process is charged;
    a file given by path is charged (the study trains one per run); the GS has no record."""
    import copy
    from types import SimpleNamespace

    from ials_zoo.baselines.aip_record import predictor_record
    from ials_zoo.influence.files import load_predictor
    from ials_zoo.influence.ials import pretrained_path
    from ials_zoo.influence.specs import parse_simulator

    shipped = load_predictor(pretrained_path(ENV, AGENT))
    cached, made = copy.deepcopy(shipped), copy.deepcopy(shipped)
    cached.source, made.source = tmp_path / "cached.pt", None
    trained = parse_simulator("ials")
    records = {name: predictor_record(SimpleNamespace(predictor=p), trained)
               for name, p in (("shipped", shipped), ("cached", cached), ("made", made))}
    assert [records[n]["charged"] for n in ("shipped", "cached", "made")] == [False, False, True]
    assert records["shipped"]["file"] == f"ials_zoo/influence/pretrained/{ENV}__{AGENT}.pt"
    assert records["shipped"]["sha256"] and records["cached"]["file"] is None is records["made"]["file"]
    given = predictor_record(SimpleNamespace(predictor=shipped), parse_simulator(str(pretrained_path(ENV, AGENT))))
    assert given["charged"] is True and given["file"].endswith(f"{ENV}__{AGENT}.pt")
    assert predictor_record(SimpleNamespace(predictor=None), None) is None


def test_the_update_size_is_the_domains_unless_given():
    from ials_zoo.baselines import ippo
    from ials_zoo.baselines.multiagent import fill_update_size
    from ials_zoo.core.domains import get_domain

    warehouse, traffic = get_domain("warehouse_v0"), get_domain("traffic_grid_v0")
    # the warehouse's learners measured best with 2,048 samples in 256s (docs/ablation.md)
    assert ppo_single.update_size(ppo_single.Args(n_envs=8), warehouse) == (256, 256)
    assert ppo_single.update_size(ppo_single.Args(n_envs=8), traffic) == (64, 128)
    assert ppo_single.update_size(ppo_single.Args(n_envs=8, n_steps=32, batch_size=64), warehouse) == (32, 64)
    for domain, expected in ((warehouse, (2048, 256)), (traffic, (512, 128))):
        args = ippo.Args(env_id=domain.env_id)
        fill_update_size(args, domain)
        assert (args.samples_per_update, args.batch_size) == expected
    args = ippo.Args(env_id="warehouse_v0", samples_per_update=256, batch_size=64)
    fill_update_size(args, warehouse)
    assert (args.samples_per_update, args.batch_size) == (256, 64)


def test_a_checkpoint_without_the_state_of_an_exact_resume_is_refused_by_name(tmp_path):
    """A checkpoint of the earlier SB3 format (weights and optimiser only) cannot continue the
    run exactly: the resume says so instead of failing on a missing key."""
    import torch

    out = tmp_path / "run"
    args = dict(TINY, total_timesteps=512, eval_every=256, final_eval_episodes=2)
    ppo_single.main(ppo_single.Args(simulator="gs", out_dir=str(out), **args))
    state = torch.load(out / "checkpoint.pt", weights_only=True)
    torch.save({"policy": state["models"]["policy"]["policy"]}, out / "checkpoint.pt")
    status = json.loads((out / "status.json").read_text())
    status.pop("run_id")  # a run of that version: its checkpoints carried no binding either
    info = json.loads((out / "checkpoint.json").read_text())
    info.pop("run")
    (out / "checkpoint.json").write_text(json.dumps(info))
    (out / "status.json").write_text(json.dumps(dict(status, state="failed")))
    with pytest.raises(ValueError, match="earlier version"):
        ppo_single.main(ppo_single.Args(simulator="gs", out_dir=str(out), resume=True, **args))


def test_a_run_says_this_machines_speed_after_its_first_stretch(tmp_path, capsys):
    """The opening estimate is the study's speed; after the first stretch of training the run
    says what it measured here and what that makes of the rest, once."""
    import re

    from ials_zoo.baselines import ippo

    ippo.main(ippo.Args(env_id="warehouse_v0", agents="robot_0,robot_1", env_options='{"robots": [2, 2]}', n_envs=2,
                        samples_per_update=128, batch_size=64, n_epochs=1, hidden="16", total_timesteps=1024,
                        eval_every=256, eval_episodes=1, final_eval_episodes=2, progress=False,
                        out_dir=str(tmp_path / "run")))
    lines = [x for x in capsys.readouterr().out.splitlines() if "measured here" in x]
    assert len(lines) == 1, lines
    m = re.search(r"measured here: ([\d,]+) steps per agent/s \(([\d,]+) agent-steps/s\) over the first ([\d,]+)", lines[0])
    rate, joint, first = (int(g.replace(",", "")) for g in m.groups())
    # the first stretch ends at the first checkpoint: a quarter of --eval-every, at least an update
    assert first == 128 and abs(joint - 2 * rate) <= 2 and "of training left" in lines[0]


@pytest.mark.parametrize("env_id, per_map", [("sumo_net_v0", True), ("warehouse_v0", False)])
def test_the_opening_estimate_scales_with_the_learners_only_where_they_are_the_cost(env_id, per_map, tmp_path):
    """A real network costs its map's steps whatever the number of learning lights (8 or 21 take
    about the same time per step, docs/sumo_net.md): its estimate is the study's steps of all
    agents per second. Elsewhere the cost is per agent, and the estimate grows with them."""
    import re
    from types import SimpleNamespace

    from ials_zoo.baselines.driver import RunPlan, estimate_text
    from ials_zoo.core.domains import get_domain
    from ials_zoo.core.extras import study_of

    domain, study = get_domain(env_id), study_of(env_id)

    def minutes(agents: int, simulator: str, options=None) -> float:
        plan = RunPlan("ippo", env_id, [f"a{k}" for k in range(agents)], options or {}, 0, 36_000, 512, 12_000, 3,
                       20, 1, tmp_path, {}, {})
        text = estimate_text(plan, SimpleNamespace(simulator=simulator), domain)
        value, unit = re.search(r"about ([\d.]+) (min|s|h)", text).groups()
        return float(value) * {"s": 1 / 60, "min": 1.0, "h": 60.0}[unit]

    # (on a GS with scripted agents the per-agent estimate adds their cost: the IALS alone here)
    for simulator in ("gs", "ials") if per_map else ("ials",):
        few, many = minutes(8, simulator), minutes(21, simulator)
        if per_map:
            step = study.joint_step_seconds(simulator)
            assert few == many == pytest.approx(36_000 * step / 60, rel=0.02)
            # but two maps do not: on quiet cores IPPO took 659-767 s on ingolstadt21 and 98 s on cologne8
            big, small = minutes(21, simulator, {"net": "ingolstadt21"}), minutes(8, simulator, {"net": "cologne8"})
            assert big > 2.5 * small, (simulator, big, small)
        else:
            assert many == pytest.approx(few * 21 / 8, rel=0.05)
