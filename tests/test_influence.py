"""Influence predictors and data sets on synthetic data (no domain needed).

The synthetic data has a known conditional law of ``u_t`` given the d-set history, so the
cross-entropy a predictor can reach is known: a trained AIP must approach the true
conditional entropy and beat the marginal.
"""

import numpy as np
import pytest

from ials_zoo.core.region import RegionSpec
from ials_zoo.influence.constant import FixedPredictor, MarginalPredictor, RecordedPredictor, UniformPredictor
from ials_zoo.influence.dataset import InfluenceDataset
from ials_zoo.influence.files import load_predictor, save_predictor
from ials_zoo.influence.metrics import cross_entropy_per_source, evaluate_cross_entropy
from ials_zoo.influence.networks import GRUPredictor, MLPPredictor, untrained_predictor

D = 6


def _region(agent="a0", domain="synthetic_v0"):
    return RegionSpec(
        domain,
        agent,
        ("s0", "s1"),
        (2, 4),
        {"dset": tuple(f"d{i}" for i in range(D)), "full": tuple(f"f{i}" for i in range(D + 2))},
    )


def _entropy(p):
    p = np.asarray(p)
    return float(-(p * np.log(p)).sum())


# Source 0 (a bit) copies d_{t-lag}[0] with prob 0.9; source 1 (4 classes) equals the 2-bit
# number 2*d[1] + d[2] with prob 0.7, else one of the 3 others uniformly.
TRUE_CE = (_entropy([0.9, 0.1]) + _entropy([0.7, 0.1, 0.1, 0.1])) / 2  # 0.633 nats
MARGINAL_CE = (np.log(2) + np.log(4)) / 2  # 1.040 nats


def synthetic(E=120, T=40, seed=0, lag=0):
    rng = np.random.default_rng(seed)
    d = (rng.random((E, T, D)) < 0.5).astype(np.uint8)
    src = np.zeros_like(d)
    src[:, lag:] = d[:, : T - lag]
    u0 = (rng.random((E, T)) < np.where(src[..., 0] == 1, 0.9, 0.1)).astype(np.int64)
    cls = 2 * src[..., 1].astype(np.int64) + src[..., 2]
    other = (cls + rng.integers(1, 4, size=(E, T))) % 4
    u1 = np.where(rng.random((E, T)) < 0.7, cls, other)
    if lag:  # before the lagged input exists, u is uniform noise
        u0[:, :lag] = rng.integers(0, 2, size=(E, lag))
        u1[:, :lag] = rng.integers(0, 4, size=(E, lag))
    full = np.concatenate([d, np.zeros((E, T, 2), np.uint8)], axis=-1)
    return InfluenceDataset(_region(), {"dset": d, "full": full}, np.stack([u0, u1], -1), {"seed": seed})


@pytest.fixture(scope="module")
def trained_mlp():
    from ials_zoo.influence.train import train_predictor

    return train_predictor(synthetic(), arch="mlp", epochs=25, progress=False)


def test_trained_mlp_reaches_the_true_conditional_entropy(trained_mlp):
    pred, report = trained_mlp
    ce = report["cross_entropy"]
    # 4,800 test-free training steps: the trained AIP must be within 0.05 nats of the
    # entropy floor (0.633) and far below the marginal (1.040) and the untrained network.
    assert ce["trained"]["test"] == pytest.approx(TRUE_CE, abs=0.06)
    assert ce["trained"]["test"] < ce["marginal"]["test"] - 0.3
    assert ce["marginal"]["test"] == pytest.approx(MARGINAL_CE, abs=0.02)
    assert ce["uniform"]["test"] == pytest.approx(MARGINAL_CE, abs=1e-9)  # no domain: uniform
    assert ce["untrained"]["test"] > ce["trained"]["test"] + 0.3
    assert report["dataset"]["train_episodes"] == 108 and report["dataset"]["test_episodes"] == 12
    # The numpy predictor reproduces the report's number on fresh data.
    fresh = synthetic(E=60, seed=7)
    assert evaluate_cross_entropy(pred, fresh) == pytest.approx(TRUE_CE, abs=0.06)


def test_gru_uses_memory_where_mlp_cannot():
    from ials_zoo.influence.train import train_predictor

    data = synthetic(E=120, T=40, lag=2, seed=3)
    gru, rep_g = train_predictor(data, arch="gru", epochs=25, progress=False, lr=3e-3, batch_size=8)
    mlp, rep_m = train_predictor(data, arch="mlp", epochs=10, progress=False)
    # With u_t depending on d_{t-2}, the feed-forward net sees nothing useful (marginal CE)
    # and the GRU gets close to the floor (slightly above: the first 2 steps are noise).
    floor = (38 * TRUE_CE + 2 * MARGINAL_CE) / 40
    assert rep_m["cross_entropy"]["trained"]["test"] > MARGINAL_CE - 0.03
    assert rep_g["cross_entropy"]["trained"]["test"] < floor + 0.1
    assert isinstance(gru, GRUPredictor) and isinstance(mlp, MLPPredictor)


@pytest.mark.parametrize("arch", ["gru", "mlp"])
def test_numpy_inference_matches_torch(arch):
    import torch

    from ials_zoo.influence.networks import init_arrays
    from ials_zoo.influence.train import _torch_modules

    region = _region()
    arrays = init_arrays(arch, D, 16, 6, seed=5)
    net = _torch_modules()[arch](D, 16, 6)
    net.load_numpy(arrays)
    pred = (GRUPredictor if arch == "gru" else MLPPredictor)(region, hidden=16, arrays=net.to_numpy())
    x = (np.random.default_rng(0).random((3, 7, D)) < 0.5).astype(np.uint8)
    with torch.no_grad():
        logits = net(torch.from_numpy(x.astype(np.float32))).numpy()
    pred.reset(3)
    for t in range(7):
        p0, p1 = pred.probs(x[:, t])
        ref0 = torch.softmax(torch.from_numpy(logits[:, t, :2]), -1).numpy()
        ref1 = torch.softmax(torch.from_numpy(logits[:, t, 2:]), -1).numpy()
        np.testing.assert_allclose(p0, ref0, atol=1e-5)
        np.testing.assert_allclose(p1, ref1, atol=1e-5)


def test_sample_follows_the_probabilities():
    region = _region()
    pred = UniformPredictor(region, probs=[[0.8, 0.2], [0.1, 0.2, 0.3, 0.4]])
    n = 20_000
    pred.reset(n)
    u = pred.sample(np.zeros((n, D), np.uint8), np.random.default_rng(0))
    assert u.dtype == np.int64 and u.shape == (n, 2)
    freq0 = np.bincount(u[:, 0], minlength=2) / n
    freq1 = np.bincount(u[:, 1], minlength=4) / n
    # 5 standard errors of a proportion at n = 20,000 is at most 0.018.
    np.testing.assert_allclose(freq0, [0.8, 0.2], atol=0.018)
    np.testing.assert_allclose(freq1, [0.1, 0.2, 0.3, 0.4], atol=0.018)


def test_gru_state_resets_and_advances():
    pred = untrained_predictor(_region(), arch="gru", seed=1)
    x = np.ones((2, D), np.uint8)
    pred.reset(2)
    a = pred.probs_padded(x).copy()
    b = pred.probs_padded(x).copy()
    assert not np.allclose(a, b)  # the hidden state moved
    pred.reset(2)
    np.testing.assert_allclose(pred.probs_padded(x), a)
    with pytest.raises(ValueError, match=r"shape \[n, 6\]"):
        pred.probs(np.ones((2, D + 1), np.uint8))
    with pytest.raises(ValueError, match="reset"):
        pred.probs(np.ones((3, D), np.uint8))


def test_constant_predictors():
    region = _region()
    fixed = FixedPredictor(region, 0.1)
    fixed.reset(1)
    p0, p1 = fixed.probs(np.zeros((1, D), np.uint8))
    np.testing.assert_allclose(p0[0], [0.9, 0.1])
    np.testing.assert_allclose(p1[0], [0.9, 0.1 / 3, 0.1 / 3, 0.1 / 3])
    f3 = FixedPredictor(region, 0.3, null_class=1)
    f3.reset(1)
    np.testing.assert_allclose(f3.probs(np.zeros((1, D), np.uint8))[1][0], [0.1, 0.7, 0.1, 0.1])
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        FixedPredictor(region, 1.5)
    with pytest.raises(ValueError, match="null_class"):
        FixedPredictor(region, 0.1, null_class=3)  # source 0 has 2 classes
    uni = UniformPredictor(region)
    assert evaluate_cross_entropy(uni, synthetic(E=4)) == pytest.approx(MARGINAL_CE)
    data = synthetic(E=10)
    marg = MarginalPredictor.fit(data)
    expected = np.bincount(data.influences[..., 1].ravel(), minlength=4) + 0.5
    np.testing.assert_allclose(marg.table[1], expected / expected.sum())
    with pytest.raises(ValueError, match="summing to 1"):
        UniformPredictor(region, probs=[[0.5, 0.6], [0.25] * 4])


def test_recorded_predictor_replays_its_episode_whatever_the_dsets():
    region = _region()
    u = np.array([[0, 3], [1, 0], [1, 2]])
    rec = RecordedPredictor(region, u)
    rng = np.random.default_rng(0)
    for _ in range(2):  # a reset starts the recording again
        rec.reset(2)
        draws = [rec.sample(rng.integers(0, 2, (2, D)).astype(np.uint8), rng) for _ in range(4)]
        np.testing.assert_array_equal(draws[:3], np.stack([u, u], axis=1))
        np.testing.assert_array_equal(draws[3], [u[-1], u[-1]])  # past the end: the last step
    rec.reset(1)
    p0, p1 = rec.probs(np.zeros((1, D), np.uint8))
    np.testing.assert_array_equal(p1[0], [0, 0, 0, 1])
    with pytest.raises(ValueError, match="shape"):
        RecordedPredictor(region, u[:, :1])
    with pytest.raises(ValueError, match="outside"):
        RecordedPredictor(region, [[2, 0]])  # source 0 has 2 classes


def test_cross_entropy_definition():
    # Hand-computed: a fixed predictor on 2 steps, mean over steps then over sources.
    region = _region()
    d = np.zeros((1, 2, D), np.uint8)
    u = np.array([[[1, 0], [0, 3]]])
    data = InfluenceDataset(region, {"dset": d, "full": np.zeros((1, 2, D + 2), np.uint8)}, u)
    pred = FixedPredictor(region, 0.2)
    per = cross_entropy_per_source(pred, data)
    np.testing.assert_allclose(per, [-(np.log(0.2) + np.log(0.8)) / 2, -(np.log(0.8) + np.log(0.2 / 3)) / 2])
    assert evaluate_cross_entropy(pred, data) == pytest.approx(per.mean())


@pytest.mark.parametrize("kind", ["gru", "mlp", "fixed", "uniform", "marginal"])
def test_predictor_file_roundtrip(tmp_path, kind):
    region = _region()
    data = synthetic(E=6)
    pred = {
        "gru": lambda: untrained_predictor(region, "gru", seed=2),
        "mlp": lambda: untrained_predictor(region, "mlp", dset_kind="full", seed=2),
        "fixed": lambda: FixedPredictor(region, 0.25),
        "uniform": lambda: UniformPredictor(region, probs=[[0.3, 0.7], [0.25] * 4]),
        "marginal": lambda: MarginalPredictor.fit(data),
    }[kind]()
    path = save_predictor(pred, tmp_path / "p.pt")
    back = load_predictor(path, env_id="synthetic_v0", agent="a0")
    assert type(back) is type(pred) and back.dset_kind == pred.dset_kind
    assert back.region == region
    assert back.metadata["package_version"] and back.metadata["created"]
    assert evaluate_cross_entropy(back, data) == pytest.approx(evaluate_cross_entropy(pred, data), abs=1e-6)
    assert not list(tmp_path.glob(".*"))  # no temporary file left behind


def test_predictor_file_errors(tmp_path):
    pred = untrained_predictor(_region(), "gru", seed=0)
    path = save_predictor(pred, tmp_path / "p.pt")
    with pytest.raises(ValueError, match=r"agent 'a0'.*not for agent 'robot_3'"):
        load_predictor(path, agent="robot_3")
    with pytest.raises(ValueError, match=r"domain 'synthetic_v0', not 'warehouse_v0'"):
        load_predictor(path, env_id="warehouse_v0")
    truncated = tmp_path / "t.pt"
    truncated.write_bytes(path.read_bytes()[:200])
    with pytest.raises(ValueError, match="not an ials_zoo influence predictor"):
        load_predictor(truncated)
    other = tmp_path / "other.pt"
    import torch

    torch.save({"weights": torch.zeros(3)}, other)
    with pytest.raises(ValueError, match="not an ials_zoo influence predictor"):
        load_predictor(other)
    with pytest.raises(FileNotFoundError):
        load_predictor(tmp_path / "missing.pt")


def test_dataset_file_roundtrip_and_errors(tmp_path):
    data = synthetic(E=5, T=7)
    path = data.save(tmp_path / "d.npz")
    back = InfluenceDataset.load(path, env_id="synthetic_v0", agent="a0")
    assert back.region == data.region and back.metadata["seed"] == 0
    for k in ("dset", "full"):
        np.testing.assert_array_equal(back.dsets[k], data.dsets[k])
    np.testing.assert_array_equal(back.influences, data.influences)
    with pytest.raises(ValueError, match="agent 'a0', not 'b'"):
        InfluenceDataset.load(path, agent="b")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(path.read_bytes()[:100])
    with pytest.raises(ValueError, match="not an ials_zoo influence data set"):
        InfluenceDataset.load(bad)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, x=np.zeros(3))
    with pytest.raises(ValueError, match="not an ials_zoo influence data set"):
        InfluenceDataset.load(foreign)
    with pytest.raises(ValueError, match="out of range"):
        InfluenceDataset(data.region, data.dsets, data.influences + 3)
    with pytest.raises(ValueError, match="expected"):
        InfluenceDataset(data.region, {"dset": data.dsets["dset"][:, :3], "full": data.dsets["full"]}, data.influences)
    train, test = data.split(0.2, seed=0)
    assert len(test) == 1 and len(train) == 4 and not set(train) & set(test)


@pytest.mark.parametrize("classes", [(2, 4), (4, 4, 4)])
def test_network_sampling_follows_its_probabilities(classes):
    # Both sampling paths (equal class counts: reshape; mixed: padded gather).
    region = RegionSpec(
        "synthetic_v0", "a0", tuple(f"s{i}" for i in range(len(classes))), classes,
        {"dset": tuple(f"d{i}" for i in range(D)), "full": tuple(f"f{i}" for i in range(D))},
    )
    pred = untrained_predictor(region, arch="mlp", seed=3)
    pred.w_out *= 8  # sharpen the random net so the probabilities are far from uniform
    n = 20_000
    d = np.tile((np.arange(D) % 2).astype(np.uint8), (n, 1))
    pred.reset(n)
    probs = [p[0] for p in pred.probs(d)]
    u = pred.sample(d, np.random.default_rng(1))
    assert u.dtype == np.int64 and u.shape == (n, len(classes))
    for m, k in enumerate(classes):
        freq = np.bincount(u[:, m], minlength=k) / n
        assert len(freq) == k
        np.testing.assert_allclose(freq, probs[m], atol=0.018)  # 5 se at n = 20,000


def _rare_events(agent_seed: int, E=30, T=300):
    """Sources that are rarely active (as a car entering a lane: 2-9% of steps), at rates
    that depend weakly on the d-set."""
    rng = np.random.default_rng(agent_seed)
    d = (rng.random((E, T, D)) < 0.5).astype(np.uint8)
    u0 = (rng.random((E, T)) < 0.03 + 0.06 * d[..., 0]).astype(np.int64)
    u1 = np.where(rng.random((E, T)) < 0.92, 0, rng.integers(1, 4, size=(E, T)))
    full = np.concatenate([d, np.zeros((E, T, 2), np.uint8)], axis=-1)
    return InfluenceDataset(_region(f"a{agent_seed}"), {"dset": d, "full": full}, np.stack([u0, u1], -1))


def _calibration_error(pred, data) -> float:
    """Mean over the rare classes of |log(mean predicted probability / empirical rate)| on
    ``data`` (teacher forcing)."""
    u = data.influences
    E, T, _ = u.shape
    pred.reset(E)
    p_sum = np.zeros((2, 4))
    for t in range(T):
        p_sum += pred.probs_padded(data.dsets["dset"][:, t]).sum(axis=0)
    predicted = np.concatenate([p_sum[0, 1:2], p_sum[1, 1:4]]) / (E * T)
    empirical = np.array([(u[..., 0] == 1).mean(), *[(u[..., 1] == k).mean() for k in (1, 2, 3)]])
    return float(np.abs(np.log(predicted / empirical)).mean())


def test_decaying_learning_rate_calibrates_rare_classes():
    """At a constant rate Adam's last iterate wanders, and with it the output bias of a rare
    class: traffic's AIPs then predicted some lanes' entry rates 30-47% off on their own
    training data. Decayed linearly to zero, a trained AIP's mean probability of every rare
    class matches its rate on the data it was trained on (the bias's gradient is
    sum(p - y), zero at the optimum)."""
    from ials_zoo.influence.train import train_predictors

    agents = [f"a{k}" for k in range(6)]
    data = {a: _rare_events(k) for k, a in enumerate(agents)}
    errors = {}
    for schedule in ("linear", "constant"):
        preds, report = train_predictors(data, "mlp", hidden=128, lr=3e-3, epochs=20, batch_size=256,
                                         test_fraction=0.0, lr_schedule=schedule)
        assert report["hyperparameters"]["lr_schedule"] == schedule
        errors[schedule] = [_calibration_error(preds[a], data[a]) for a in agents]
    assert max(errors["linear"]) < 0.03, errors
    # the constant rate's last iterate is measurably worse (it is what the schedule fixes)
    assert np.mean(errors["constant"]) > 2 * np.mean(errors["linear"]), errors


def test_lr_schedule_ends_at_zero_and_rejects_unknown_names(monkeypatch):
    import torch

    from ials_zoo.errors import BadInput
    from ials_zoo.influence.train import _scheduler, train_predictor, train_predictors

    w = torch.nn.Parameter(torch.zeros(1))
    opt = torch.optim.Adam([w], lr=0.5)
    sched = _scheduler(opt, "linear", 4)
    rates = []
    for _ in range(4):
        rates.append(opt.param_groups[0]["lr"])
        opt.step()
        sched.step()
    assert rates == pytest.approx([0.5, 0.375, 0.25, 0.125])
    assert opt.param_groups[0]["lr"] == 0.0
    # the trainers count their updates right: the last update runs at lr / updates
    seen = []
    step = torch.optim.Adam.step

    def recording_step(self, *args, **kwargs):
        seen.append(self.param_groups[0]["lr"])
        return step(self, *args, **kwargs)

    monkeypatch.setattr(torch.optim.Adam, "step", recording_step)
    data = synthetic(E=20, T=10)  # 18 training episodes x 10 steps
    train_predictor(data, arch="mlp", epochs=3, lr=0.3, batch_size=64, progress=False)  # 3 x ceil(180 / 64)
    assert len(seen) == 9 and seen[0] == pytest.approx(0.3) and seen[-1] == pytest.approx(0.3 / 9)
    seen.clear()
    train_predictors({"a0": data}, "gru", lr=0.3, epochs=2, batch_size=4)  # 2 x ceil(18 / 4)
    assert len(seen) == 10 and seen[-1] == pytest.approx(0.3 / 10)
    with pytest.raises(BadInput, match="lr schedule 'cosine'"):
        train_predictor(synthetic(E=4, T=5), arch="mlp", epochs=1, progress=False, lr_schedule="cosine")
