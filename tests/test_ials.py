"""Data collection, the IALS env/VecEnv and the factory on the warehouse domain."""

import gymnasium
import numpy as np
import pytest

import ials_zoo
from ials_zoo.influence.constant import FixedPredictor, UniformPredictor
from ials_zoo.influence.dataset import InfluenceDataset, collect
from ials_zoo.influence.files import save_predictor
from ials_zoo.influence.ials import IALSEnv, IALSVecEnv, make_ials, make_ials_vec_env
from ials_zoo.influence.networks import GRUPredictor, untrained_predictor
from ials_zoo.warehouse import regions as R

ENV = "warehouse_v0"
AGENT = "robot_20"


@pytest.fixture(scope="module")
def data():
    return collect(ENV, AGENT, steps=2000, seed=3, progress=False)


def test_collect_shapes_and_metadata(data, tmp_path):
    assert data.n_episodes == 20 and data.episode_length == 100
    assert data.dsets["dset"].shape == (20, 100, 24) and data.dsets["full"].shape == (20, 100, 37)
    assert data.influences.shape == (20, 100, 4) and data.influences.dtype == np.int64
    m = data.metadata
    assert (m["env_id"], m["agent"], m["steps"], m["seed"], m["policy"]) == (ENV, AGENT, 2000, 3, "uniform_random")
    assert m["collect_seconds"] > 0 and m["package_version"] == ials_zoo.__version__
    assert data.region == R.region_spec(AGENT)
    # d_0 is the reset state: robot at the centre, so no "on item cell" bit and position 12.
    assert (data.dsets["dset"][:, 0, 12:] == 0).all()
    assert (data.dsets["full"][:, 0, R.CENTRE] == 1).all()
    back = InfluenceDataset.load(data.save(tmp_path / "w.npz"), env_id=ENV, agent=AGENT)
    np.testing.assert_array_equal(back.dsets["dset"], data.dsets["dset"])
    # Same seed, same data: the collection is reproducible.
    again = collect(ENV, AGENT, steps=200, seed=3, progress=False)
    np.testing.assert_array_equal(again.influences, data.influences[:2])


def test_collect_pairs_d_t_with_the_u_t_of_the_following_step(data):
    # u_t says a neighbour stands on shared cell b after step t, so it took the item there:
    # the item bit of b in d_{t+1} is 0 unless a new item appeared at once (p = 0.02). The
    # neighbours walk to items, so in d_t (before the step) the bit is usually 1. A collector
    # that paired u_t with d_{t+1} or d_{t-1} would see the opposite pattern.
    items = data.dsets["dset"][..., :12].astype(bool)
    u = data.influences
    before, after = [], []
    for s in range(4):
        for k in range(3):
            hit = u[:, :-1, s] == k
            before.append(items[:, :-1, 3 * s + k][hit])
            after.append(items[:, 1:, 3 * s + k][hit])
    before, after = np.concatenate(before), np.concatenate(after)
    assert before.size > 100
    assert after.mean() < 0.06
    assert before.mean() > 0.5


def test_collect_accepts_a_policy_and_rejects_bad_input():
    calls = []

    def always_up(obs):
        calls.append(obs.shape)
        return 0

    d = collect(ENV, AGENT, steps=50, policy=always_up, progress=False)
    assert d.n_steps == 100 and len(calls) == 100 and d.metadata["policy"] == "always_up"
    # Always "up" from the centre: the robot reaches the top shelf cell (2 moves) and stays.
    assert (d.dsets["dset"][:, 2:, 12 + 10] == 1).all()
    with pytest.raises(ValueError, match="unknown agent 'robot_99'"):
        collect(ENV, "robot_99", steps=10, progress=False)
    with pytest.raises(ValueError, match="steps must be >= 1"):
        collect(ENV, AGENT, steps=0, progress=False)
    with pytest.raises(TypeError, match="policy must be"):
        collect(ENV, AGENT, steps=10, policy=42, progress=False)


def test_collect_in_several_processes_is_the_concatenation_of_its_shares():
    from ials_zoo.influence.dataset import worker_seeds

    both = collect(ENV, AGENT, steps=300, seed=4, progress=False, workers=2)
    seeds = worker_seeds(4, 2)
    assert worker_seeds(4, 1) == [4] and len(set(seeds)) == 2
    parts = [collect(ENV, AGENT, steps=150, seed=s, progress=False) for s in seeds]
    assert both.n_episodes == 4  # 150 steps per process, rounded up to 2 episodes of 100
    np.testing.assert_array_equal(both.influences, np.concatenate([p.influences for p in parts]))
    for kind in both.dsets:
        np.testing.assert_array_equal(both.dsets[kind], np.concatenate([p.dsets[kind] for p in parts]))
    assert both.metadata["workers"] == 2 and both.metadata["worker_seeds"] == seeds
    assert both.metadata["steps"] == 400 and both.metadata["steps_requested"] == 300
    with pytest.raises(ValueError, match="workers must be a positive int"):
        collect(ENV, AGENT, steps=10, progress=False, workers=0)
    with pytest.raises(ValueError, match="cannot be pickled"):
        collect(ENV, AGENT, steps=10, progress=False, workers=2, policy=lambda obs: 0)


def test_ials_env_api():
    from gymnasium.utils.env_checker import check_env

    env = make_ials(ENV, AGENT, predictor="untrained", seed=0)
    assert isinstance(env, IALSEnv) and isinstance(env.predictor, GRUPredictor)
    check_env(env, skip_render_check=True)
    obs, info = env.reset(seed=5)
    assert env.observation_space.contains(obs) and obs[R.CENTRE] == 1
    rollout = []
    for t in range(100):
        obs, r, term, trunc, info = env.step(t % 4)
        rollout.append((obs.copy(), r, info["influence"].copy()))
        assert not term and trunc == (t == 99)
        assert info["influence"].shape == (4,) and env.region.influence_space.contains(info["influence"])
    with pytest.raises(RuntimeError, match="reset"):
        env.step(0)
    # Reproducible from the seed.
    env.reset(seed=5)
    for t, (o, r, u) in enumerate(rollout[:30]):
        obs, rew, _, _, info = env.step(t % 4)
        np.testing.assert_array_equal(obs, o)
        np.testing.assert_array_equal(info["influence"], u)
    env.close()


def test_gymnasium_registration():
    env = gymnasium.make("ials_zoo/IALS-warehouse_v0", agent=AGENT, predictor="uniform")
    obs, _ = env.reset(seed=0)
    assert obs.shape == (37,)
    assert isinstance(env.unwrapped.predictor, UniformPredictor)
    env.close()


def test_vec_env_auto_reset_and_infos():
    venv = make_ials_vec_env(ENV, AGENT, n_envs=4, predictor="untrained", seed=1)
    assert isinstance(venv, IALSVecEnv) and venv.num_envs == 4
    obs = venv.reset()
    assert obs.shape == (4, 37)
    total = np.zeros(4)
    for t in range(100):
        obs, rew, dones, infos = venv.step(np.full(4, t % 4))
        total += rew
        assert rew.dtype == np.float32 and dones.shape == (4,)
        if t < 99:
            assert not dones.any() and infos[0] == {}
    assert dones.all()
    for i, info in enumerate(infos):
        assert info["TimeLimit.truncated"] is True
        assert info["terminal_observation"].shape == (37,)
        assert info["episode"]["l"] == 100 and info["episode"]["r"] == pytest.approx(total[i], abs=1e-4)
    # The returned observations start the next episode (robots back at the centre).
    assert (obs[:, R.CENTRE] == 1).all()
    assert venv.get_attr("max_cycles") == [100] * 4 and venv.env_is_wrapped(object) == [False] * 4
    venv.seed(3)
    a = venv.reset()
    venv.seed(3)
    np.testing.assert_array_equal(venv.reset(), a)
    venv.close()


def test_vec_env_trains_with_sb3():
    import torch
    from stable_baselines3 import PPO

    venv = make_ials_vec_env(ENV, AGENT, n_envs=2, predictor="untrained", seed=0)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        model = PPO("MlpPolicy", venv, n_steps=100, batch_size=200, n_epochs=1, seed=0,
                    device="cpu", policy_kwargs={"net_arch": [16]})
        model.learn(200)
    finally:
        torch.set_num_threads(threads)
    # Episode statistics reached SB3 through infos["episode"] (no Monitor wrapper).
    assert len(model.ep_info_buffer) == 2 and model.ep_info_buffer[0]["l"] == 100
    venv.close()


def test_fixed_predictor_uses_the_domains_null_class():
    import dataclasses

    from ials_zoo.core.domains import get_domain, register_domain, unregister_domain

    # The warehouse's "no influence" class is 3: the neighbour is on no shared cell.
    env = make_ials(ENV, AGENT, predictor="fixed:0.3")
    assert isinstance(env.predictor, FixedPredictor) and env.predictor.p == 0.3
    # P(neighbour elsewhere) = 0.7, each shared cell 0.1.
    np.testing.assert_allclose(env.predictor.table[:, R.NONE], 0.7)
    np.testing.assert_allclose(env.predictor.table[:, :3], 0.1)
    # The domain's declaration is what counts.
    register_domain(dataclasses.replace(get_domain(ENV), null_influence=0), replace=True)
    try:
        env = make_ials(ENV, AGENT, predictor="fixed:0.3")
        np.testing.assert_allclose(env.predictor.table[:, 0], 0.7)
    finally:
        unregister_domain(ENV)
    assert get_domain(ENV).null_influence == R.NONE


def test_predictor_names_and_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown agent 'robot_99'"):
        make_ials(ENV, "robot_99", predictor="untrained")
    with pytest.raises(ValueError, match="unknown influence predictor 'bogus'"):
        make_ials(ENV, AGENT, predictor="bogus")
    with pytest.raises(ValueError, match="fixed:P"):
        make_ials(ENV, AGENT, predictor="fixed:lots")
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        make_ials(ENV, AGENT, predictor="fixed:2")
    other = save_predictor(untrained_predictor(R.region_spec("robot_3")), tmp_path / "r3.pt")
    with pytest.raises(ValueError, match="agent 'robot_3'.*not for agent 'robot_20'"):
        make_ials(ENV, AGENT, predictor=str(other))
    with pytest.raises(ValueError, match="robot_3, not warehouse_v0/robot_20"):
        make_ials(ENV, AGENT, predictor=untrained_predictor(R.region_spec("robot_3")))
    with pytest.raises(ValueError, match="another region setting"):
        make_ials(ENV, AGENT, predictor=untrained_predictor(R.region_spec(AGENT)), item_lifetime=8)
    with pytest.raises(ValueError, match="reads the 'dset' d-set, not 'full'"):
        make_ials(ENV, AGENT, predictor=untrained_predictor(R.region_spec(AGENT)), dset_kind="full")
    with pytest.raises(ValueError, match="n_envs"):
        make_ials_vec_env(ENV, AGENT, n_envs=0, predictor="untrained")


def test_predictor_object_is_copied_per_env():
    pred = untrained_predictor(R.region_spec(AGENT), dset_kind="full", seed=4)
    a = make_ials(ENV, AGENT, predictor=pred, seed=0)
    b = make_ials(ENV, AGENT, predictor=pred, seed=0)
    assert a.predictor is not b.predictor
    a.reset(seed=1)
    b.reset(seed=1)
    for t in range(20):
        oa = a.step(t % 4)[0]
        ob = b.step(t % 4)[0]
        np.testing.assert_array_equal(oa, ob)


def test_trained_uses_the_cache(tmp_path, monkeypatch):
    # A non-default setting has no shipped AIP; a cached one for that setting is used
    # instead of collecting and training.
    from ials_zoo.influence import ials

    monkeypatch.setenv("IALS_ZOO_CACHE", str(tmp_path))
    region = R.region_spec(AGENT, item_probability=0.05)
    pred = untrained_predictor(region, seed=9)
    path = ials._cache_path(region, "gru", "dset")
    assert path.parent == tmp_path / "aip"
    save_predictor(pred, path)
    env = make_ials(ENV, AGENT, predictor="trained", item_probability=0.05)
    np.testing.assert_array_equal(env.predictor.w_ih, pred.w_ih)
    with pytest.raises(FileNotFoundError, match="train-aip"):
        ials.trained_predictor(ENV, AGENT, options={"item_probability": 0.07}, train_if_missing=False)


def test_collect_and_train_aip_commands(tmp_path, capsys):
    import json

    from ials_zoo.cli import main
    from ials_zoo.influence.files import load_predictor

    data = tmp_path / "wh.npz"
    assert main(["collect", "--env", ENV, "--agent", AGENT, "--steps", "300", "--seed", "2",
                 "--no-progress", "--out", str(data)]) == 0
    assert InfluenceDataset.load(data).n_steps == 300
    out = tmp_path / "aip.pt"
    report = tmp_path / "report.json"
    assert main(["train-aip", "--data", str(data), "--epochs", "2", "--no-progress",
                 "--report", str(report), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    for row in ("trained", "untrained", "uniform", "marginal", "test CE"):
        assert row in text
    pred = load_predictor(out, env_id=ENV, agent=AGENT)
    assert isinstance(pred, GRUPredictor)  # the warehouse's default architecture
    rep = json.loads(report.read_text())
    assert rep["dataset"]["steps"] == 300 and rep["hyperparameters"]["epochs"] == 2
    assert pred.metadata["cross_entropy"]["trained"]["test"] == rep["cross_entropy"]["trained"]["test"]
    capsys.readouterr()
    # neither --data nor --env/--agent; then a file that is not a data set: one line, exit 2
    assert main(["train-aip", "--out", str(out), "--no-progress"]) == 2
    assert capsys.readouterr().err.startswith("ials-zoo train-aip: give --data")
    assert main(["train-aip", "--data", str(report), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ials-zoo train-aip: not an ials_zoo influence data set") and "Traceback" not in err


def test_trained_architecture_choice_uses_the_cache(tmp_path, monkeypatch):
    from ials_zoo.influence import ials

    monkeypatch.setenv("IALS_ZOO_CACHE", str(tmp_path))
    region = R.region_spec(AGENT)
    mlp = untrained_predictor(region, arch="mlp", seed=1)
    save_predictor(mlp, ials._cache_path(region, "mlp", "dset"))
    env = make_ials(ENV, AGENT, predictor="trained:mlp")
    np.testing.assert_array_equal(env.predictor.w1, mlp.w1)
    with pytest.raises(ValueError, match="trained:gru"):
        make_ials(ENV, AGENT, predictor="trained:lstm")


def test_influence_rates_tell_a_fixed_probability_apart_from_none():
    from ials_zoo.influence.rates import influence_rates

    # traffic: one entry bit per incoming lane, so the mean is the entry rate
    none = influence_rates("traffic_grid_v0", "tls_12", "fixed:0.0", episodes=1)
    some = influence_rates("traffic_grid_v0", "tls_12", "fixed:0.5", episodes=1)
    assert none["steps"] == some["steps"] == 300
    assert none["influence_mean"] == 0.0 and 0.4 < some["influence_mean"] < 0.6
    assert some["observation_mean"] > none["observation_mean"]
    with pytest.raises(ValueError, match="episodes"):
        influence_rates("traffic_grid_v0", "tls_12", "fixed:0.5", episodes=0)


def test_nothing_is_trained_behind_the_callers_back(tmp_path, monkeypatch, capsys):
    """make_ials (and gymnasium.make through it) never collects data or trains: without a
    shipped or cached AIP it says how to get one; predictor='train' opts in."""
    monkeypatch.setenv("IALS_ZOO_CACHE", str(tmp_path))
    with pytest.raises(FileNotFoundError, match="predictor='train'"):
        make_ials(ENV, "robot_3", robots=(2, 2))
    with pytest.raises(FileNotFoundError, match="train-aip"):
        gymnasium.make("ials_zoo/IALS-warehouse_v0", agent="robot_3", robots=(2, 2))
    assert not list(tmp_path.rglob("*.pt")) and "collecting" not in capsys.readouterr().out
    from ials_zoo.influence.specs import parse_predictor

    assert parse_predictor("train").train_if_missing and not parse_predictor("trained").train_if_missing
    assert str(parse_predictor("train:gru")) == "train:gru"
