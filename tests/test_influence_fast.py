"""The single-history (n=1) inference path of the network AIPs equals the batched path."""

import copy

import numpy as np
import pytest

from ials_zoo.influence.networks import GRUPredictor, MLPPredictor
from ials_zoo.warehouse import regions as R


@pytest.mark.parametrize(
    "cls,kind", [(GRUPredictor, "dset"), (GRUPredictor, "full"), (MLPPredictor, "dset")]
)
def test_single_history_sampling_equals_general_path(cls, kind):
    """Same d-sets and rng stream: ``sample`` at n=1 (memoised input projection, buffers)
    gives the same draws, the same hidden state and the same probabilities as the general
    batched code run on one history, over episodes with resets."""
    region = R.region_spec("robot_20")
    fast = cls(region, dset_kind=kind, seed=4)
    ref = copy.deepcopy(fast)
    rng_d = np.random.default_rng(0)
    pool = (rng_d.random((30, fast.dset_size)) < 0.3).astype(np.uint8)  # repeated d-sets
    r1, r2 = np.random.default_rng(7), np.random.default_rng(7)
    for episode in range(3):
        fast.reset(1)
        ref.reset(1)
        for t in range(50):
            d = pool[rng_d.integers(len(pool))][None]
            u_fast = fast.sample(d, r1)
            u_ref = ref._sample_logits(ref._logits(d), r2)
            assert u_fast.dtype == u_ref.dtype and u_fast.shape == (1, R.N_SOURCES)
            np.testing.assert_array_equal(u_fast, u_ref)
            if cls is GRUPredictor:
                np.testing.assert_array_equal(fast.h, ref.h)
        np.testing.assert_array_equal(fast.probs_padded(d), ref.probs_padded(d))
    assert r1.random() == r2.random()  # same number of draws consumed


def test_single_history_cache_follows_new_weights():
    region = R.region_spec("robot_20")
    pred = GRUPredictor(region, seed=0)
    other = GRUPredictor(region, seed=1)
    d = np.zeros((1, pred.dset_size), np.uint8)
    pred.reset(1)
    pred.sample(d, np.random.default_rng(0))
    pred.set_arrays(other._arrays())
    pred.reset(1)
    other.reset(1)
    pred.sample(d, np.random.default_rng(0))
    other.sample(d, np.random.default_rng(0))
    np.testing.assert_array_equal(pred.h, other.h)


@pytest.mark.parametrize("clone", ["deepcopy", "pickle"])
def test_copied_predictor_continues_identically(clone):
    """A copy taken mid-episode (e.g. by resolve_predictor or a subprocess env) has working
    scratch buffers of its own and continues exactly like the original."""
    import pickle

    region = R.region_spec("robot_20")
    pred = GRUPredictor(region, seed=2)
    pred.reset(1)
    pool = (np.random.default_rng(3).random((5, pred.dset_size)) < 0.3).astype(np.uint8)
    rng = np.random.default_rng(0)
    for t in range(5):
        pred.sample(pool[t % 5][None], rng)
    other = copy.deepcopy(pred) if clone == "deepcopy" else pickle.loads(pickle.dumps(pred))
    r1, r2 = np.random.default_rng(9), np.random.default_rng(9)
    for t in range(20):
        d = pool[t % 5][None]
        np.testing.assert_array_equal(pred.sample(d, r1), other.sample(d, r2))
        np.testing.assert_array_equal(pred.h, other.h)
