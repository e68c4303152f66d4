"""The single-copy (n_envs=1) fast path of the warehouse local simulator equals the array path."""

import numpy as np
import pytest

from ials_zoo.warehouse import regions as R
from ials_zoo.warehouse.local import WarehouseLocalSimulator


def _pair(**options):
    fast = WarehouseLocalSimulator("robot_20", n_envs=1, **options)
    ref = WarehouseLocalSimulator("robot_20", n_envs=1, **options)
    ref._scalar = False  # force the general numpy path on a single copy
    assert fast._scalar
    return fast, ref


def _assert_same(a, b):
    obs_a, dsets_a = a
    obs_b, dsets_b = b
    assert obs_a.dtype == obs_b.dtype and obs_a.shape == obs_b.shape
    np.testing.assert_array_equal(obs_a, obs_b)
    assert dsets_a.keys() == dsets_b.keys()
    for k in dsets_a:
        assert dsets_a[k].dtype == dsets_b[k].dtype
        np.testing.assert_array_equal(dsets_a[k], dsets_b[k])


@pytest.mark.parametrize("lifetime,prob", [(None, 0.3), (3, 0.3), (None, 0.02)])
def test_single_copy_path_equals_array_path(lifetime, prob):
    """Same seed, actions and influences: same observations, rewards, d-sets and states at
    every step, including the random item appearances (same rng stream) and resets."""
    fast, ref = _pair(item_probability=prob, item_lifetime=lifetime)
    rng = np.random.default_rng(1)
    rewarded = removed = 0
    for episode in range(3):
        seed = None if episode == 2 else episode  # seed=None continues the stream
        _assert_same(fast.reset(seed=seed), ref.reset(seed=seed))
        for t in range(60):
            a = rng.integers(4, size=1)
            u = rng.integers(4, size=(1, 4))
            if t % 2:  # both entry points of the fast path
                obs, rew, dsets = fast.step(a, u)
            else:
                rew = np.array([fast.step_single(int(a[0]), *u[0].tolist())])
                obs, dsets = fast.observe()
            ages_before = ref.get_state()[1]
            obs_r, rew_r, dsets_r = ref.step(a, u)
            _assert_same((obs, dsets), (obs_r, dsets_r))
            assert rew.dtype == rew_r.dtype and rew[0] == rew_r[0]
            for x, y in zip(fast.get_state(), ref.get_state()):
                np.testing.assert_array_equal(x, y)
            rewarded += rew_r[0] > 0
            removed += int(((ages_before > 0) & (ref.get_state()[1] == 0)).sum())
    assert rewarded > 0 and removed > 0  # collections and removals were exercised


def test_single_copy_set_state_and_new_items():
    fast, ref = _pair(item_probability=0.5, item_lifetime=4)
    fast.reset(seed=0)
    ref.reset(seed=0)
    rng = np.random.default_rng(2)
    for _ in range(40):
        pos = int(rng.choice(np.setdiff1d(np.arange(R.N_CELLS), R.CORNERS)))
        ages = rng.integers(0, 6, size=(1, 12)) * (rng.random((1, 12)) < 0.5)
        fast.set_state([pos], ages)
        ref.set_state([pos], ages)
        _assert_same(fast.observe(), ref.observe())
        a, u = rng.integers(4, size=1), rng.integers(4, size=(1, 4))
        new = rng.random((1, 12)) < 0.3
        out_f, out_r = fast.step(a, u, new_items=new), ref.step(a, u, new_items=new)
        _assert_same((out_f[0], out_f[2]), (out_r[0], out_r[2]))
        assert out_f[1][0] == out_r[1][0]
        for x, y in zip(fast.get_state(), ref.get_state()):
            np.testing.assert_array_equal(x, y)
    # new_items does not consume the rng: the streams are still in step afterwards
    a, u = np.array([0]), np.full((1, 4), 3)
    for _ in range(70):
        out_f, out_r = fast.step(a, u), ref.step(a, u)
        np.testing.assert_array_equal(out_f[0], out_r[0])


def test_single_copy_outputs_are_fresh_arrays():
    fast, _ = _pair(item_probability=0.0)
    obs, dsets = fast.reset(seed=0)
    obs[0, 0] = 7.0
    dsets["dset"][0, 0] = 9
    obs2, dsets2 = fast.observe()
    assert obs2[0, 0] == 0.0 and dsets2["dset"][0, 0] == 0


@pytest.mark.parametrize("predictor", ["untrained", "uniform"])
def test_ials_env_fast_path_equals_general_path(predictor):
    """IALSEnv over the scalar single-copy LS == IALSEnv over the array path: same
    observations, rewards, truncations and sampled influences for the same seed/actions."""
    from ials_zoo.influence.ials import IALSEnv, make_ials

    fast = make_ials("warehouse_v0", "robot_20", predictor=predictor, seed=3, item_probability=0.2)
    ls = WarehouseLocalSimulator("robot_20", n_envs=1, item_probability=0.2)
    ls._scalar = False
    import copy

    ref = IALSEnv(ls, copy.deepcopy(fast.predictor), seed=3)
    assert fast._fast and not ref._fast
    rng = np.random.default_rng(0)
    for _ in range(2):
        o1, _ = fast.reset()
        o2, _ = ref.reset()
        np.testing.assert_array_equal(o1, o2)
        done = False
        while not done:
            a = int(rng.integers(4))
            action = [a, np.int64(a), np.array(a), np.array([a])][a % 4]  # accepted forms
            s1, s2 = fast.step(action), ref.step(action)
            assert s1[0].dtype == s2[0].dtype and s1[0].flags.writeable
            np.testing.assert_array_equal(s1[0], s2[0])
            assert type(s1[1]) is type(s2[1]) and s1[1] == s2[1]
            assert s1[2:4] == s2[2:4]
            np.testing.assert_array_equal(s1[4]["influence"], s2[4]["influence"])
            assert s1[4]["influence"].dtype == np.int64
            done = s1[3]
    for bad in (4, -1, True, 1.0):
        with pytest.raises((ValueError, TypeError)):
            fast.reset()
            fast.step(bad)
