"""Autoregressive AIPs, P(u_t | d_<=t, u_<t), checked against what they must compute: on data
whose influence persists (a neighbour that lingers) and whose d-sets say nothing, an
autoregressive AIP samples the chain's own persistence and a memoryless one cannot; the
stacked (multi-agent) AIPs compute what the single ones compute, and remember their draws;
the variant survives a save and a load. AIPs that read several past draws (``influence_lags``)
learn arrivals that come two steps apart, which one past draw cannot show."""

from __future__ import annotations

import numpy as np
import pytest

from ials_zoo.core.domains import get_domain
from ials_zoo.influence.dataset import DSET_KINDS, InfluenceDataset

ENV, OPTIONS = "warehouse_v0", {"robots": (2, 2)}
AGENTS = ["robot_0", "robot_1", "robot_2"]
STAY = 0.9


def _region(agent="robot_0"):
    return get_domain(ENV).region_spec(agent, **OPTIONS)


def _lingering_data(region, episodes=60, steps=40, seed=0) -> InfluenceDataset:
    """Every source a Markov chain: it keeps its class with probability STAY, else redraws it
    uniformly; the d-sets are all zero (they carry no information)."""
    rng = np.random.default_rng(seed)
    K = np.asarray(region.influence_classes)
    u = np.zeros((episodes, steps, len(K)), np.int64)
    u[:, 0] = rng.integers(K, size=(episodes, len(K)))
    for t in range(1, steps):
        fresh = rng.integers(K, size=(episodes, len(K)))
        stay = rng.random((episodes, len(K))) < STAY
        u[:, t] = np.where(stay, u[:, t - 1], fresh)
    dsets = {k: np.zeros((episodes, steps, region.dset_size(k)), np.uint8) for k in DSET_KINDS}
    return InfluenceDataset(region, dsets, u)


def _sampled_persistence(predictor, region, episodes=200, steps=40, seed=1) -> float:
    rng = np.random.default_rng(seed)
    predictor.reset(episodes)
    d = np.zeros((episodes, region.dset_size("dset")), np.uint8)
    u = np.stack([predictor.sample(d, rng) for _ in range(steps)], axis=1)
    return float((u[:, 1:] == u[:, :-1]).mean())


@pytest.mark.parametrize("arch", ["mlp", "gru"])
def test_an_autoregressive_aip_samples_the_persistence_a_memoryless_one_loses(arch):
    from ials_zoo.influence.metrics import evaluate_cross_entropy
    from ials_zoo.influence.train import train_predictor

    region = _region()
    data = _lingering_data(region)
    K = np.asarray(region.influence_classes)
    truth = float(np.mean(STAY + (1 - STAY) / K))  # P(u_t = u_{t-1}) of the chain
    kw = {"mlp": dict(epochs=30, lr=1e-2), "gru": dict(epochs=40, lr=1e-2, batch_size=8)}[arch]
    memoryless, _ = train_predictor(data, arch, hidden=16, progress=False, **kw)
    remembering, report = train_predictor(data, arch, hidden=16, progress=False, autoregressive=True, **kw)
    assert report["autoregressive"] and remembering.autoregressive
    assert abs(_sampled_persistence(remembering, region) - truth) < 0.04
    # without u_<t the draws are independent: P(stay) = sum_k p_k^2, about 1/K
    assert _sampled_persistence(memoryless, region) < truth - 0.4
    # teacher-forced cross-entropy: the chain's own entropy rate is far below ln K
    assert evaluate_cross_entropy(remembering, data) < 0.6 * evaluate_cross_entropy(memoryless, data)


@pytest.mark.parametrize("arch,lags,clock", [("mlp", 1, 0), ("gru", 1, 0), ("mlp", 3, 0), ("gru", 3, 0),
                                             ("mlp", 1, 4), ("gru", 3, 4)])
def test_stacked_autoregressive_aips_compute_what_each_one_computes(arch, lags, clock):
    from ials_zoo.influence.networks import untrained_predictor
    from ials_zoo.influence.stacked import StackedPredictor

    kw = dict(hidden=8, autoregressive=True, influence_lags=lags, clock_horizon=clock)
    preds = [untrained_predictor(_region(a), arch, seed=i, **kw) for i, a in enumerate(AGENTS)]
    singles = [untrained_predictor(_region(a), arch, seed=i, **kw) for i, a in enumerate(AGENTS)]
    n = 2
    stacked = StackedPredictor(preds, n_envs=n)
    rng = np.random.default_rng(0)
    D, K = preds[0].dset_size, np.asarray(preds[0].n_classes)
    for p in singles:
        p.reset(n)
    for _ in range(6):
        d = rng.integers(0, 2, size=(len(AGENTS) * n, D)).astype(np.uint8)
        u = rng.integers(K, size=(len(AGENTS) * n, len(K)))
        together = stacked.probs_padded(d)
        for i, p in enumerate(singles):
            rows = slice(i * n, (i + 1) * n)
            np.testing.assert_allclose(together[rows], p.probs_padded(d[rows]), atol=1e-5)
            p.observe(u[rows])
        stacked.observe(u)
    # sample() remembers its own draws: the next step reads them as observe() would make it
    twin = StackedPredictor([untrained_predictor(_region(a), arch, seed=i, **kw) for i, a in enumerate(AGENTS)],
                            n_envs=n)
    d0 = np.zeros((len(AGENTS) * n, D), np.uint8)
    stacked.reset()
    twin.reset()
    u0 = stacked.sample(d0)
    twin.probs_padded(d0)
    twin.observe(u0)
    np.testing.assert_allclose(stacked.probs_padded(d0), twin.probs_padded(d0), atol=1e-6)


def test_the_variant_survives_a_save_and_a_load(tmp_path):
    from ials_zoo.influence.files import load_predictor, save_predictor
    from ials_zoo.influence.networks import untrained_predictor

    pred = untrained_predictor(_region(), "gru", hidden=8, autoregressive=True)
    back = load_predictor(save_predictor(pred, tmp_path / "aip.pt"))
    assert back.autoregressive and back.input_size == pred.dset_size + int(np.sum(pred.n_classes))
    plain = load_predictor(save_predictor(untrained_predictor(_region(), "gru", hidden=8), tmp_path / "p.pt"))
    assert not plain.autoregressive and plain.input_size == plain.dset_size


def test_several_lags_survive_a_save_and_a_load_and_older_files_read_one(tmp_path):
    from ials_zoo.influence.files import load_predictor, save_predictor
    from ials_zoo.influence.networks import untrained_predictor

    pred = untrained_predictor(_region(), "mlp", hidden=8, autoregressive=True, influence_lags=3)
    back = load_predictor(save_predictor(pred, tmp_path / "aip.pt"))
    assert back.influence_lags == 3 and back.input_size == pred.dset_size + 3 * int(np.sum(pred.n_classes))
    one = untrained_predictor(_region(), "mlp", hidden=8, autoregressive=True)
    assert "influence_lags" not in one._config()  # the files of one-lag AIPs are what they were
    assert load_predictor(save_predictor(one, tmp_path / "one.pt")).influence_lags == 1


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_influence_lags_must_be_a_positive_int(bad):
    from ials_zoo.errors import BadInput
    from ials_zoo.influence.networks import untrained_predictor

    with pytest.raises(BadInput, match="influence_lags"):
        untrained_predictor(_region(), "mlp", hidden=8, autoregressive=True, influence_lags=bad)


def test_a_memoryless_aip_takes_no_lags():
    from ials_zoo.errors import BadInput
    from ials_zoo.influence.networks import untrained_predictor
    from ials_zoo.influence.train import train_predictor

    assert untrained_predictor(_region(), "mlp", hidden=8).influence_lags == 0
    with pytest.raises(BadInput, match="needs an autoregressive AIP"):
        untrained_predictor(_region(), "gru", hidden=8, influence_lags=3)
    with pytest.raises(BadInput, match="needs an autoregressive AIP"):
        train_predictor(_lingering_data(_region(), episodes=4, steps=5), "mlp", epochs=1, progress=False,
                        influence_lags=2)


def test_previous_influences_holds_each_lag_latest_first():
    from ials_zoo.influence.base import one_hot_influences, previous_influences

    K = np.array([2, 3])
    offsets = np.concatenate([[0], np.cumsum(K)])
    u = np.random.default_rng(0).integers(K, size=(2, 5, 2))
    lagged = previous_influences(u, offsets, lags=3)
    onehot = one_hot_influences(u, offsets)
    assert lagged.shape == (2, 5, 15)
    for t in range(5):
        for k in range(1, 4):
            want = onehot[:, t - k] if t - k >= 0 else np.zeros((2, 5))
            np.testing.assert_array_equal(lagged[:, t, (k - 1) * 5:k * 5], want)


def _pairs_data(region, episodes=80, steps=60, start=0.06, follow=0.9, seed=0) -> InfluenceDataset:
    """Binary sources whose arrivals come in pairs two steps apart (a platoon): a pair starts
    with probability ``start`` at a quiet step, and its second arrival follows two steps later
    with probability ``follow``; nothing arrives in between. The d-sets carry no information."""
    rng = np.random.default_rng(seed)
    M = region.n_sources
    u = np.zeros((episodes, steps, M), np.int64)
    second = np.zeros((episodes, M), bool)  # a pair's second arrival is due at this step
    pending = np.zeros((episodes, M), bool)  # ... at the next step
    for t in range(steps):
        busy = (u[:, t - 1] == 1) if t else np.zeros((episodes, M), bool)
        new = ~busy & ~second & ~pending & (rng.random((episodes, M)) < start)
        u[:, t] = second | new
        second, pending = pending, new & (rng.random((episodes, M)) < follow)
    dsets = {k: np.zeros((episodes, steps, region.dset_size(k)), np.uint8) for k in DSET_KINDS}
    return InfluenceDataset(region, dsets, u)


def _share_of_gaps_of_two(u: np.ndarray) -> float:
    gaps = [np.diff(np.flatnonzero(u[e, :, m])) for e in range(u.shape[0]) for m in range(u.shape[2])]
    gaps = np.concatenate(gaps)
    return float(np.mean(gaps == 2))


def test_aips_that_read_three_lags_make_the_pairs_one_lag_cannot():
    from ials_zoo.influence.train import format_report, train_predictor

    region = get_domain("traffic_grid_v0").region_spec("tls_0")
    data = _pairs_data(region)
    truth = _share_of_gaps_of_two(data.influences)
    assert truth > 0.4  # the data is made of pairs
    shares = {}
    for lags in (1, 3):
        pred, report = train_predictor(data, "mlp", hidden=16, epochs=30, lr=1e-2, progress=False,
                                       autoregressive=True, influence_lags=lags)
        assert report["influence_lags"] == lags and pred.influence_lags == lags
        assert ("reading its last draw" if lags == 1 else f"reading its last {lags} draws") in format_report(report)
        rng = np.random.default_rng(1)
        pred.reset(300)
        d = np.zeros((300, region.dset_size("dset")), np.uint8)
        shares[lags] = _share_of_gaps_of_two(np.stack([pred.sample(d, rng) for _ in range(60)], axis=1))
    assert abs(shares[3] - truth) < 0.05, (shares, truth)
    assert shares[1] < truth - 0.2, (shares, truth)  # one lag: the second arrival is a fresh draw


def _late_data(region, episodes=80, steps=60, start=20, rate=0.3, seed=0) -> InfluenceDataset:
    """Binary sources that never fire before step ``start`` of an episode (the grid is still
    empty) and fire with probability ``rate`` after; the d-sets carry no information."""
    rng = np.random.default_rng(seed)
    u = (rng.random((episodes, steps, region.n_sources)) < rate).astype(np.int64)
    u[:, :start] = 0
    dsets = {k: np.zeros((episodes, steps, region.dset_size(k)), np.uint8) for k in DSET_KINDS}
    return InfluenceDataset(region, dsets, u)


def test_an_aip_with_a_clock_waits_for_the_first_arrivals_one_without_cannot(tmp_path):
    from ials_zoo.influence.files import load_predictor, save_predictor
    from ials_zoo.influence.stacked import StackedPredictor
    from ials_zoo.influence.train import train_predictor, train_predictors

    region = get_domain("traffic_grid_v0").region_spec("tls_0")
    data = _late_data(region)
    early = {}
    for clock in (0, 40):
        pred, report = train_predictor(data, "mlp", hidden=16, epochs=30, lr=1e-2, progress=False,
                                       clock_horizon=clock)
        assert report.get("clock_horizon", 0) == clock and pred.clock_horizon == clock
        if clock:
            pred = load_predictor(save_predictor(pred, tmp_path / "clock.pt"))
            assert pred.clock_horizon == clock and pred.input_size == region.dset_size("dset") + 1
        rng = np.random.default_rng(1)
        pred.reset(300)
        d = np.zeros((300, region.dset_size("dset")), np.uint8)
        u = np.stack([pred.sample(d, rng) for _ in range(60)], axis=1)
        early[clock] = (u[:, :10].mean(), u[:, 40:].mean())
    # waits, then the rate (a small network learns a ramp around step 20, not a step: the test
    # looks at steps 0-9 and 40-59)
    assert early[40][0] < 0.04 and abs(early[40][1] - 0.3) < 0.05, early
    assert early[0][0] > 0.1, early  # without a clock every step looks alike
    # the stacked (multi-agent) path reads the same clock
    sets, _ = train_predictors({"tls_0": data}, "mlp", hidden=16, epochs=30, lr=1e-2, clock_horizon=40)
    stacked = StackedPredictor(list(sets.values()), n_envs=300)
    stacked.seed(2)
    u = np.stack([stacked.sample(np.zeros((300, region.dset_size("dset")), np.uint8)) for _ in range(60)], axis=1)
    assert u[:, :10].mean() < 0.04 and abs(u[:, 40:].mean() - 0.3) < 0.05, (u[:, :10].mean(), u[:, 40:].mean())


@pytest.mark.parametrize("bad", [-1, 1.5, True, "40"])
def test_clock_horizon_must_be_a_whole_number_of_steps(bad):
    from ials_zoo.errors import BadInput
    from ials_zoo.influence.networks import untrained_predictor

    with pytest.raises(BadInput, match="clock_horizon"):
        untrained_predictor(_region(), "mlp", hidden=8, clock_horizon=bad)
