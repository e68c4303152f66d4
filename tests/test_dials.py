"""DIALS's pieces and runs: stacked AIPs and their training, the batched PPO learner, the
distributed training loop on every backend, and its errors.

Runs use warehouse_v0 with a 2x2 grid of robots (4 learners), tiny networks and budgets."""

import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
from same_run import assert_same_run, policy_weights

ENV = "warehouse_v0"
OPTIONS = {"robots": [2, 2]}
AGENTS = ["robot_0", "robot_1", "robot_2", "robot_3"]
# small PPO updates (the defaults' 512 samples x 10 epochs would make these tests slow)
TINY = dict(env_id=ENV, agents=",".join(AGENTS), env_options=json.dumps(OPTIONS), total_timesteps=256, n_envs=2,
            samples_per_update=128, batch_size=64, n_epochs=3,
            collect_steps=200, aip_epochs=1, eval_episodes=1, final_eval_episodes=2, progress=False)


# -- stacked AIPs ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def datasets():
    from ials_zoo.influence.dataset import collect_all

    return collect_all(ENV, AGENTS, steps=300, seed=1, gs_options=OPTIONS, progress=False)


def test_stacked_predictor_rows_do_not_depend_on_the_batch(datasets):
    from ials_zoo.influence.multi import resolve_predictor_set
    from ials_zoo.influence.stacked import StackedPredictor

    preds = resolve_predictor_set("untrained", ENV, AGENTS[:2], seed=3, options=OPTIONS)
    both, alone = StackedPredictor(preds, n_envs=3), StackedPredictor(preds[1:], n_envs=3)
    both.seed(7)
    alone.seed(7)
    single = preds[1]
    single.reset(3)
    d = {a: datasets[a].dsets["dset"][0] for a in AGENTS[:2]}  # [T, D] of episode 0
    for t in range(20):
        rows = np.stack([np.repeat(d[a][t][None], 3, axis=0) for a in AGENTS[:2]]).reshape(6, -1)
        p_both = both.probs_padded(rows)
        p_alone = alone.probs_padded(rows[3:])
        np.testing.assert_allclose(p_both[3:], p_alone, rtol=1e-6)
        np.testing.assert_allclose(p_alone, single.probs_padded(rows[3:]), rtol=1e-5, atol=1e-7)
    both.reset()
    alone.reset()
    for t in range(20):
        rows = np.stack([np.repeat(d[a][t][None], 3, axis=0) for a in AGENTS[:2]]).reshape(6, -1)
        np.testing.assert_array_equal(both.sample(rows)[3:], alone.sample(rows[3:]))


def test_training_every_aip_at_once_is_training_each_alone(datasets):
    from ials_zoo.influence.train import train_predictors

    all_four, _ = train_predictors(datasets, "gru", hidden=8, epochs=2, seed=4)
    one, report = train_predictors({"robot_2": datasets["robot_2"]}, "gru", hidden=8, epochs=2, seed=4)
    for k, v in one["robot_2"]._arrays().items():
        np.testing.assert_allclose(all_four["robot_2"]._arrays()[k], v, rtol=1e-5, atol=1e-6)
    assert np.isfinite(report["mean_test_cross_entropy"])
    # a warm start continues from the given networks: one more epoch equals three from scratch
    again, rep = train_predictors(datasets, "gru", hidden=8, epochs=1, seed=4, init=all_four)
    assert rep["warm_start"]
    moved = again["robot_0"]._arrays()["w_out"] - all_four["robot_0"]._arrays()["w_out"]
    assert 0 < np.abs(moved).max() < 0.1


def test_predictor_sets_round_trip_and_name_their_domain(tmp_path):
    from ials_zoo.influence.files import load_predictor_set, save_predictor_set
    from ials_zoo.influence.multi import resolve_predictor_set

    preds = resolve_predictor_set("untrained", ENV, AGENTS, seed=0, options=OPTIONS)
    path = save_predictor_set(preds, tmp_path / "set.pt", {"note": "test"})
    back = load_predictor_set(path, env_id=ENV)
    assert list(back) == AGENTS
    for p in preds:
        for k, v in p._arrays().items():
            np.testing.assert_array_equal(back[p.region.agent]._arrays()[k], v)
    with pytest.raises(ValueError, match="holds predictors of 'warehouse_v0'"):
        load_predictor_set(path, env_id="traffic_grid_v0")
    (tmp_path / "junk.pt").write_bytes(b"not a torch file")
    with pytest.raises(ValueError):
        load_predictor_set(tmp_path / "junk.pt")


# -- the batched learner --------------------------------------------------------------------

def _ppo(agents, input_size=6, n_actions=3, **kw):
    from ials_zoo.learners.batched_ppo import BatchedPPO, PPOConfig

    cfg = PPOConfig(**{"n_steps": 16, "n_envs": 4, "batch_size": 32, "hidden": (16, 16), **kw})
    return BatchedPPO(agents, input_size, n_actions, cfg, seed=5, total_updates=10)


def test_batched_ppo_agents_do_not_depend_on_each_other():
    """An agent's weights, actions and updates are bitwise the same alone or beside others
    (odd widths included: 37 inputs, 5 actions, as in the warehouse)."""
    rng = np.random.default_rng(0)
    both, alone = _ppo(["a", "b"], input_size=37, n_actions=5), _ppo(["b"], input_size=37, n_actions=5)
    for _ in range(3):
        obs = rng.standard_normal((2, 4, 37)).astype(np.float32)
        act_both, v_both, lp_both = both.act(obs)
        act_alone, v_alone, lp_alone = alone.act(obs[1:])
        np.testing.assert_array_equal(act_both[1:], act_alone)
        np.testing.assert_array_equal(v_both[1:], v_alone)
        np.testing.assert_array_equal(lp_both[1:], lp_alone)
        N = 64
        batch = (rng.standard_normal((2, N, 37)), rng.integers(5, size=(2, N)), rng.standard_normal((2, N)) - 1.6,
                 rng.standard_normal((2, N)), rng.standard_normal((2, N)), rng.standard_normal((2, N)))
        both.update(*batch)
        alone.update(*(x[1:] for x in batch))
    for (wb, bb), (wa, ba) in zip(both.actor_layers(), alone.actor_layers()):
        np.testing.assert_array_equal(wb[1:], wa)
        np.testing.assert_array_equal(bb[1:], ba)


class _Bandit:
    """A multi-agent vector env where agent i is rewarded for choosing the action its
    observation points to (episodes of 8 steps)."""

    def __init__(self, agents, n_envs, seed=0):
        self.agents, self.n_envs = agents, n_envs
        self.rng = np.random.default_rng(seed)
        self.t = 0

    def _obs(self):
        self.target = self.rng.integers(3, size=(len(self.agents), self.n_envs))
        obs = np.zeros((len(self.agents), self.n_envs, 6), np.float32)
        np.put_along_axis(obs, self.target[..., None], 1.0, axis=-1)
        return obs

    def reset(self, seed=None):
        self.t = 0
        return self._obs()

    def step(self, actions):
        reward = (actions == self.target).astype(np.float64)
        self.t += 1
        return self._obs(), reward, self.t % 8 == 0


def test_batched_ppo_learns_a_contextual_bandit():
    from ials_zoo.learners.rollout import RolloutTrainer

    learner = _ppo(["a", "b"], learning_rate=3e-3, ent_coef=0.0, n_epochs=4, anneal_lr=False)
    trainer = RolloutTrainer(learner, _Bandit(["a", "b"], 4), frame_stack=1, seed=0)
    for _ in range(60):
        trainer.collect_and_update()
    trainer.episode_returns()
    for _ in range(5):
        trainer.collect_and_update()
    returns = trainer.episode_returns()
    assert returns is not None and np.all(returns > 7.0), returns  # of 8; chance is 8/3


# -- DIALS runs -----------------------------------------------------------------------------

def _dials(tmp_path, name, **kw):
    from ials_zoo.baselines import dials

    args = dials.Args(**{**TINY, "out_dir": str(tmp_path / name), **kw})
    return dials.main(args), tmp_path / name


def test_dials_gives_the_same_result_with_any_number_of_workers(tmp_path):
    in_process = _dials(tmp_path, "w0", workers=0)
    one = _dials(tmp_path, "w1", workers=1)
    two = _dials(tmp_path, "w2", workers=2)
    assert_same_run(in_process, one)
    assert_same_run(in_process, two)
    result, folder = two
    # it trained: the policies moved away from their initial weights, the AIPs were trained once
    assert result["track"] == "multi-agent" and result["trained_agents"] == AGENTS
    training = result["training"]
    assert training["simulator"] == "dials-once-autoregressive" and training["aip"]["refreshes"] == 1
    assert training["env_steps"] == 256 and training["workers"] == 2 and training["aip_seconds"] > 0
    assert json.loads((folder / "status.json").read_text())["state"] == "finished"
    assert {"aips.pt", "checkpoint.pt", "curve.json", "progress.csv"} <= {p.name for p in folder.iterdir()}


def test_a_recurrent_dials_run_is_the_same_on_any_workers_and_writes_a_recurrent_policy(tmp_path):
    """GRUs over 4 frames: the shards' actors (GRU first) join into one recurrent policy file."""
    from ials_zoo.policy import load_policy_file

    kw = dict(frame_stack=4, recurrent_hidden=8, aip="untrained", refresh="never")
    in_process, two = _dials(tmp_path, "g0", workers=0, **kw), _dials(tmp_path, "g2", workers=2, **kw)
    assert_same_run(in_process, two)
    net = load_policy_file(two[1] / "policy.safetensors")
    assert net.recurrent_hidden == 8 and net.frame_stack == 4 and list(net.agents) == AGENTS
    assert two[0]["training"]["hyperparameters"]["ppo"]["recurrent_hidden"] == 8


def test_traffic_dials_gives_the_same_result_with_one_and_two_workers(tmp_path):
    """Two lights, one AIP training; each worker's SUMO holds its agents' local simulators."""
    kw = dict(env_id="traffic_grid_v0", agents="tls_12,tls_13", env_options="", collect_steps=300)
    one, two = _dials(tmp_path, "t1", workers=1, **kw), _dials(tmp_path, "t2", workers=2, **kw)
    assert_same_run(one, two)
    assert one[0]["training"]["aip"]["refreshes"] == 1


def test_dials_can_train_its_aips_as_the_fidelity_report_does(tmp_path, monkeypatch):
    """--aip-training fidelity: every round trains the AIPs with the domain's fidelity settings
    (lags, clock, rate, schedule; here 2 lags and a clock of 40, whatever the defaults), the
    second round warm-started from the first, and the shards sample them (two lights, two
    workers, two rounds)."""
    import dataclasses

    from ials_zoo.core.domains import get_domain
    from ials_zoo.core.extras import dials_of
    from ials_zoo.influence.files import load_predictor_set

    d = dataclasses.replace(dials_of("traffic_grid_v0"), fidelity_aip_influence_lags=2, fidelity_aip_clock_horizon=40)
    monkeypatch.setitem(get_domain("traffic_grid_v0").extras, "dials", d)
    result, folder = _dials(tmp_path, "fid", env_id="traffic_grid_v0", agents="tls_12,tls_13", env_options="",
                            collect_steps=300, refresh="128", aip_training="fidelity", workers=2)
    training = result["training"]
    hp = training["hyperparameters"]
    assert training["simulator"] == "dials-fidelity" and hp["aip_training"] == "fidelity"
    assert (hp["aip_influence_lags"], hp["aip_clock_horizon"]) == (2, 40)
    assert training["aip"]["refreshes"] == 2 and training["aip"]["last"]["warm_start"]
    aips = load_predictor_set(folder / "aips.pt", env_id="traffic_grid_v0")
    for p in aips.values():  # what was trained, not what was asked for
        assert (p.autoregressive, p.influence_lags, p.clock_horizon) == (True, 2, 40)
        trained = p.metadata["hyperparameters"]
        assert (trained["lr"], trained["lr_schedule"]) == (d.fidelity_aip_lr, d.fidelity_aip_lr_schedule)
        assert trained["epochs"] == 1 and p.metadata["dataset"]["steps"] == 300  # the run's overrides win
    assert json.loads((folder / "status.json").read_text())["state"] == "finished"


def test_dials_on_ray_matches_the_process_backend(tmp_path):
    pytest.importorskip("ray")
    assert_same_run(_dials(tmp_path, "proc", workers=2), _dials(tmp_path, "ray", workers=2, backend="ray"))


def test_periodic_refresh_retrains_every_n_steps_and_sb3_learner_runs(tmp_path):
    result, folder = _dials(tmp_path, "refresh", refresh="128", learner="sb3", workers=0)
    aip = result["training"]["aip"]
    assert result["training"]["simulator"] == "dials-autoregressive"  # the warehouse's default AIPs
    assert aip["refreshes"] == 2 and aip["last"]["at_steps_per_agent"] == 128 and aip["last"]["warm_start"]
    from ials_zoo.influence.files import load_predictor_set

    assert list(load_predictor_set(folder / "aips.pt", env_id=ENV)) == AGENTS


def test_dials_trains_refreshes_and_samples_autoregressive_aips_alike_on_any_workers(tmp_path):
    from ials_zoo.influence.files import load_predictor_set

    in_process = _dials(tmp_path, "ar0", refresh="128", aip_autoregressive=True, workers=0)
    two = _dials(tmp_path, "ar2", refresh="128", aip_autoregressive=True, workers=2)
    assert_same_run(in_process, two)
    result, folder = two
    assert result["training"]["hyperparameters"]["aip_autoregressive"] is True
    assert result["training"]["aip"]["refreshes"] == 2 and result["training"]["aip"]["last"]["warm_start"]
    assert all(p.autoregressive for p in load_predictor_set(folder / "aips.pt", env_id=ENV).values())


def test_the_shared_learner_is_one_network_in_one_worker_however_many_cores(tmp_path):
    """``--learner shared`` on a batched IALS: shared PPO's network (the same weights for every
    robot, its id in the first layer's bias), in the one shard it needs by default."""
    from test_sumo_net_dials import _one_network

    from ials_zoo.policy import load_policy_file

    result, folder = _dials(tmp_path, "shared", learner="shared", aip="untrained", refresh="never")
    assert result["training"]["workers"] == 1 and result["training"]["simulator"] == "untrained-dials-shared"
    assert _one_network(load_policy_file(folder / "policy.safetensors").layers)
    _, batched = _dials(tmp_path, "batched", aip="untrained", refresh="never", workers=1)
    assert not _one_network(load_policy_file(batched / "policy.safetensors").layers)


def test_a_dials_result_is_accepted_and_verified_by_the_leaderboard(tmp_path):
    from ials_zoo.leaderboard import submit, validate_result, verify

    result, folder = _dials(tmp_path, "board", aip="untrained", refresh="never", workers=0)
    validate_result(result)
    assert result["training"]["simulator"] == "untrained-dials" and result["training"]["aip"]["variant"] == "untrained"
    (tmp_path / "lb" / "results").mkdir(parents=True)
    entry = submit(folder / "result.json", directory=tmp_path / "lb")
    (report,) = verify(entry, directory=tmp_path / "lb")
    assert report["ok"], report


def test_ippo_on_the_gs_is_the_same_with_or_without_worker_processes(tmp_path):
    from ials_zoo.baselines import ippo

    def run(name, processes):
        args = ippo.Args(env_id=ENV, agents=",".join(AGENTS), env_options=json.dumps(OPTIONS), total_timesteps=256,
                         n_envs=2, gs_processes=processes, eval_episodes=1, final_eval_episodes=2, progress=False,
                         samples_per_update=128, batch_size=64, n_epochs=3,
                         out_dir=str(tmp_path / name))
        return ippo.main(args), tmp_path / name

    local, workers = run("p0", 0), run("p2", 2)
    assert_same_run(local, workers)
    assert local[0]["training"]["simulator"] == "gs" and local[0]["track"] == "multi-agent"


@pytest.mark.parametrize("kw, message", [
    ({"refresh": "0"}, "--refresh '0'"),
    ({"agents": "robot_0,robot_99"}, "robot_99"),
    ({"aip": "uniform"}, "use --refresh never"),
    ({"aip": "nowhere.pt", "refresh": "never"}, "file not found"),
    ({"learner": "jax"}, "unknown learner"),
    ({"backend": "mpi"}, "unknown backend"),
    ({"workers": -1}, "workers must be >= 0"),
    ({"samples_per_update": 100, "n_envs": 3}, "multiple of the copies"),
    ({"ray_address": "127.0.0.1:1"}, "needs --backend ray"),
    ({"recurrent_hidden": -1}, "recurrent_hidden must be >= 0"),
    ({"recurrent_hidden": 8, "learner": "sb3"}, "needs --learner batched"),
    ({"recurrent_hidden": 8, "learner": "shared"}, "needs --learner batched"),
    ({"learner": "shared", "workers": 2}, "--learner shared is one network for every agent: --workers 1"),
    ({"aip_training": "best"}, "unknown aip_training 'best'"),
    ({"aip_training": "fidelity", "aip": "untrained", "refresh": "never"}, "needs --aip trained"),
    ({"aip_training": "fidelity", "aip_autoregressive": False}, "drop --aip-autoregressive no"),
    ({"refresh": "never"}, "would never train the AIPs"),
])
def test_bad_arguments_are_refused_before_anything_starts(tmp_path, kw, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace("[", r"\[")):
        _dials(tmp_path, "bad", **kw)
    assert not (tmp_path / "bad").exists()


def test_a_dead_ray_address_is_refused_in_seconds(tmp_path):
    from ials_zoo.dials.backends import check_ray_address

    t0 = time.monotonic()
    with pytest.raises(ValueError, match="nothing answers there"):
        check_ray_address("127.0.0.1:9", timeout=2.0)
    with pytest.raises(ValueError, match="expected host:port"):
        check_ray_address("localhost")
    assert time.monotonic() - t0 < 10


# -- worker failures ------------------------------------------------------------------------

def _specs(n_shards=2):
    from ials_zoo.baselines import dials
    from ials_zoo.baselines.multiagent import ppo_config
    from ials_zoo.dials.shard import ShardSpec
    from ials_zoo.influence.multi import resolve_predictor_set

    preds = dict(zip(AGENTS, resolve_predictor_set("untrained", ENV, AGENTS, seed=0, options=OPTIONS)))
    ppo = ppo_config(dials.Args(**{**TINY, "hidden": "8"}), 2)
    from ials_zoo.dials.shard import split_agents

    chunks = split_agents(AGENTS, n_shards)
    return [ShardSpec(ENV, c, OPTIONS, 0, 2, 1, "batched", ppo, 4, {a: preds[a] for a in c}) for c in chunks]


def _gone(pid, within=10.0):
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        try:
            with open(f"/proc/{pid}/stat") as f:
                if f.read().split(")")[-1].split()[0] == "Z":
                    return True
        except OSError:
            return True
        time.sleep(0.1)
    return False


@pytest.mark.parametrize("how", ["kill", "stop"])
def test_a_dead_or_stopped_worker_is_named_within_seconds_and_nothing_is_left(how):
    from ials_zoo.dials.backends import ProcessBackend
    from ials_zoo.runtime.processes import WorkerError

    backend = ProcessBackend(_specs(), unresponsive_after=3.0)
    pids = [w.pid for w in backend.workers]
    os.kill(pids[1], signal.SIGKILL if how == "kill" else signal.SIGSTOP)
    t0 = time.monotonic()
    said = "died" if how == "kill" else "is stopped \\(SIGSTOP"
    with pytest.raises(WorkerError, match=f"DIALS worker 1 \\(pid {pids[1]}.*{said}"):
        backend.call("train", [(128,), (128,)])
    assert time.monotonic() - t0 < 15
    assert all(_gone(p) for p in pids)


def test_a_stopped_ray_actor_is_named_within_seconds():
    pytest.importorskip("ray")
    from ials_zoo.dials.backends import RayBackend
    from ials_zoo.runtime.processes import WorkerError

    backend = RayBackend(_specs())
    try:
        pid = backend.pids[1]
        assert pid is not None
        os.kill(pid, signal.SIGSTOP)
        t0 = time.monotonic()
        with pytest.raises(WorkerError, match=f"Ray actor 1 \\(pid {pid}\\) is stopped"):
            backend.call("train", [(128,), (128,)])
        assert time.monotonic() - t0 < 15
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
        backend.close()


def test_killing_a_dials_run_leaves_no_worker_and_resume_finishes_it(tmp_path):
    """kill -9 of the training process: its workers die with it; --resume continues from the
    last checkpoint to the full budget and ends where the uninterrupted run ends."""
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "baselines.dials", "--env", ENV, "--agents", ",".join(AGENTS), "--env-options",
           json.dumps(OPTIONS), "--total-timesteps", "4096", "--eval-every", "256", "--n-envs", "2",
           "--samples-per-update", "128", "--batch-size", "64", "--n-epochs", "3",
           "--collect-steps", "200", "--aip-epochs", "1", "--eval-episodes", "1", "--final-eval-episodes", "1",
           "--workers", "2", "--no-progress", "--out-dir", str(out)]
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.Popen(cmd, cwd=root, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (out / "checkpoint.json").exists():
            time.sleep(0.2)
        assert (out / "checkpoint.json").exists(), "no checkpoint within 120 s"
        time.sleep(1.0)
        children = [int(p) for p in subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True,
                                                     text=True).stdout.split()]
        assert len(children) >= 2
        proc.kill()
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert all(_gone(p) for p in children), "a DIALS worker outlived its parent"
    done = subprocess.run(cmd + ["--resume"], cwd=root, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads((out / "result.json").read_text())
    assert result["training"]["env_steps"] == 4096
    assert json.loads((out / "status.json").read_text())["state"] == "finished"
    # and it is the run that was never killed, bit for bit
    whole = tmp_path / "whole"
    assert subprocess.run([c if c != str(out) else str(whole) for c in cmd], cwd=root, capture_output=True,
                          timeout=300).returncode == 0
    for key, value in policy_weights(whole).items():
        np.testing.assert_array_equal(policy_weights(out)[key], value, err_msg=key)
    assert json.loads((whole / "result.json").read_text())["score"] == result["score"]


def test_kill_9_of_a_ray_run_leaves_no_ray_process():
    """The local Ray cluster a run starts (raylet, GCS, dashboard and runtime-env agents, the
    actors) dies with the run even after kill -9 (a watchdog reaps it); nothing is left."""
    pytest.importorskip("ray")
    from ials_zoo.runtime.processes import _descendants, _proc_table

    cmd = [sys.executable, "-m", "baselines.dials", "--env", ENV, "--agents", ",".join(AGENTS), "--env-options",
           json.dumps(OPTIONS), "--total-timesteps", "100000", "--samples-per-update", "128", "--batch-size", "64",
           "--n-envs", "2", "--collect-steps", "200", "--aip-epochs", "1", "--eval-episodes", "1",
           "--final-eval-episodes", "1", "--workers", "2", "--backend", "ray", "--no-progress", "--out-dir",
           str(Path(tempfile.mkdtemp()) / "run")]
    root = Path(__file__).resolve().parents[1]
    # a dead cluster named where ray.init() looks (what a killed `ray start --head` leaves): the
    # run starts a Ray of its own all the same
    current = Path(tempfile.gettempdir()) / "ray" / "ray_current_cluster"
    stale = not current.exists()
    if stale:
        current.parent.mkdir(parents=True, exist_ok=True)
        current.write_text("127.0.0.1:9\n")
    proc = subprocess.Popen(cmd, cwd=root, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        family = {}
        while time.monotonic() < deadline:
            family = _descendants(proc.pid, _proc_table())
            if sum("ray::AgentShard" in _cmdline(p) for p in family) >= 2:
                break
            time.sleep(0.5)
        assert sum("ray::AgentShard" in _cmdline(p) for p in family) >= 2, "no Ray actors within 120 s"
        time.sleep(2.0)
        family = _descendants(proc.pid, _proc_table())
    finally:
        proc.kill()
        proc.wait()
        if stale:
            with contextlib.suppress(OSError):
                if current.read_text().strip() == "127.0.0.1:9":
                    current.unlink()
    left = [p for p in family if not _gone(p, within=30.0)]
    assert not left, [(p, _cmdline(p)) for p in left]



def test_kill_9_of_a_run_on_a_cluster_it_joined_leaves_the_cluster_alone(tmp_path):
    """``--ray-address``: the run's actors die with it, and the cluster it only connected to
    (started here with ``ray start --head``: GCS, raylet, agents) lives on."""
    pytest.importorskip("ray")
    import socket

    from ials_zoo.runtime.processes import _descendants, _proc_table

    # no token authentication: Ray 2.59+ turns it on for a head where ~/.ray/auth_token exists,
    # and a joining driver sends no token (an in-process ray.init() may also have set the mode)
    env = dict(os.environ, HOME=str(tmp_path), RAY_AUTH_MODE="disabled")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    # its own session: the cluster's daemons form a process group apart from this test's
    started = subprocess.run([str(Path(sys.executable).parent / "ray"), "start", "--head", f"--port={port}",
                              "--num-cpus=2", "--include-dashboard=false", "--disable-usage-stats",
                              "--node-ip-address=127.0.0.1"], env=env, capture_output=True, timeout=120,
                             start_new_session=True)
    assert started.returncode == 0, started.stderr[-2000:]
    gcs = [p for p in _proc_table() if "gcs_server" in _cmdline(p) and f"={port}" in _cmdline(p)]
    assert len(gcs) == 1, "the cluster's GCS not found"
    group = os.getpgid(gcs[0])
    assert group != os.getpgrp()
    proc, shards = None, []
    try:
        cluster = sorted(p for p in _proc_table() if _group(p) == group)
        raylet = [p for p in cluster if "raylet/raylet" in _cmdline(p)]
        assert len(raylet) == 1
        cmd = [sys.executable, "-m", "baselines.dials", "--env", ENV, "--agents", ",".join(AGENTS), "--env-options",
               json.dumps(OPTIONS), "--total-timesteps", "1000000", "--samples-per-update", "128", "--batch-size",
               "64", "--n-envs", "2", "--collect-steps", "200", "--aip-epochs", "1", "--eval-every", "500000",
               "--eval-episodes", "1", "--final-eval-episodes", "1", "--workers", "2", "--backend", "ray",
               "--ray-address", f"127.0.0.1:{port}", "--no-progress", "--out-dir", str(tmp_path / "run")]
        proc = subprocess.Popen(cmd, cwd=Path(__file__).resolve().parents[1], env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and len(shards) < 2:
            shards = [p for p in _descendants(raylet[0], _proc_table()) if "ray::AgentShard" in _cmdline(p)]
            time.sleep(0.5)
        assert len(shards) >= 2, "no Ray actors within 120 s"
        proc.kill()
        proc.wait()
        assert all(_gone(p, within=30.0) for p in shards), "the run's actors outlived it"
        alive = [p for p in cluster if not _gone(p, within=0.0)]
        assert alive == cluster, "the cluster the run joined lost processes"
    finally:
        if proc is not None and proc.poll() is None:
            proc.kill()
        for pid in shards:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        with contextlib.suppress(ProcessLookupError):
            os.killpg(group, signal.SIGKILL)
        current = Path(tempfile.gettempdir()) / "ray" / "ray_current_cluster"  # where ray.init() would look
        with contextlib.suppress(OSError):
            if current.read_text().strip().endswith(f":{port}"):
                current.unlink()


def _group(pid: int):
    try:
        return os.getpgid(pid)
    except OSError:
        return None

def _cmdline(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return f.read().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""
