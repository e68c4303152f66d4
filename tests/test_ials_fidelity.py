"""Fidelity of the IALS: statistics of the agent's region under the same (uniform random)
policy in the global simulator (GS) and in the IALS.

With the shipped trained AIP the statistics must agree; with the untrained AIP (a randomly
initialised network, the paper's untrained-IALS) they must measurably not.

Statistics are per-episode values, so episodes are the independent samples; ``se`` is the
standard error of the difference of the two means (Welch). Two kinds of check:

* *equivalence* (trained): ``|diff| + 3.3 se < margin`` -- the 99.9% confidence interval of
  the difference lies inside the margin, so passing is not luck of a noisy sample (an AIP
  off by the margin fails); the sample must be large enough that the interval's half-width
  is under 60% of the margin, so an AIP whose bias is well under 40% of it passes;
* *difference* (untrained): ``|diff| - 3.3 se > margin`` -- the interval lies outside it.

Margins are practical tolerances for an approximate model, stated per statistic below. All
seeds are fixed, so the tests are deterministic; the statistics justify the sizes.
"""

import numpy as np
import pytest

from ials_zoo.influence.dataset import collect
from ials_zoo.influence.ials import make_ials, make_ials_vec_env

Z = 3.3  # two-sided 99.9%


def _compare(gs, ials):
    gs, ials = np.asarray(gs, float), np.asarray(ials, float)
    gs, ials = gs[~np.isnan(gs)], ials[~np.isnan(ials)]
    diff = ials.mean() - gs.mean()
    se = np.sqrt(gs.var(ddof=1) / len(gs) + ials.var(ddof=1) / len(ials))
    return diff, se


def assert_equivalent(gs, ials, margin, what):
    diff, se = _compare(gs, ials)
    assert Z * se < 0.6 * margin, f"{what}: sample too small to test (se {se:.4f}, margin {margin:.4f})"
    assert abs(diff) + Z * se < margin, (
        f"{what}: GS {np.nanmean(gs):.4f} vs IALS {np.nanmean(ials):.4f} (diff {diff:+.4f} +- "
        f"{Z * se:.4f}, margin {margin:.4f})"
    )


def assert_different(gs, ials, margin, what):
    diff, se = _compare(gs, ials)
    assert abs(diff) - Z * se > margin, (
        f"{what}: GS {np.nanmean(gs):.4f} vs IALS {np.nanmean(ials):.4f} should differ by more "
        f"than {margin:.4f} (diff {diff:+.4f} +- {Z * se:.4f})"
    )


# ------------------------------------------------------------------------------ warehouse

WH, ROBOT, E_WH = "warehouse_v0", "robot_20", 200


def _item_stats(obs):
    """Per-episode statistics of a region from its observations ``[E, T, 37]`` (obs_0..obs_{T-1}).

    Returns (mean life of the items a neighbour took, items neighbours took per episode).
    An item "is taken by a neighbour" when its bit drops while the robot is not on that cell;
    its life is the number of observations it was visible in.
    """
    from ials_zoo.warehouse import regions as R

    E, T, _ = obs.shape
    items = obs[..., R.N_CELLS :] > 0.5  # [E, T, 12]
    bit = R.SHELF_INDEX[obs[..., : R.N_CELLS].argmax(-1)]  # [E, T] item bit under the robot
    on = np.zeros_like(items)
    e, t = np.nonzero(bit >= 0)
    on[e, t, bit[e, t]] = True
    seq = items.transpose(0, 2, 1).reshape(E * 12, T).astype(np.int8)  # one row per cell
    edges = np.diff(np.pad(seq, ((0, 0), (1, 1))), axis=1)
    r_start, t_start = np.nonzero(edges == 1)
    r_end, t_end = np.nonzero(edges == -1)  # np.nonzero is row-major: runs pair up in order
    assert (r_start == r_end).all()
    ep, cell = r_start // 12, r_start % 12
    inside = t_end < T  # runs still going at the end of the episode are censored
    by_neighbour = inside.copy()
    by_neighbour[inside] = ~on[ep[inside], t_end[inside], cell[inside]]
    life = (t_end - t_start)[by_neighbour]
    ep_n = ep[by_neighbour]
    counts = np.bincount(ep_n, minlength=E)
    sums = np.bincount(ep_n, weights=life, minlength=E)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_life = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    return mean_life, counts


@pytest.fixture(scope="module")
def warehouse_gs():
    data = collect(WH, ROBOT, steps=E_WH * 100, seed=11, progress=False)
    return _item_stats(data.dsets["full"].astype(np.float32))


def _warehouse_ials(predictor, seed=11):
    venv = make_ials_vec_env(WH, ROBOT, n_envs=E_WH, predictor=predictor, seed=seed)
    rng = np.random.default_rng(seed)
    obs = [venv.reset()]
    for _ in range(99):
        obs.append(venv.step(rng.integers(4, size=E_WH))[0])
    venv.close()
    return _item_stats(np.stack(obs, 1))


def test_warehouse_trained_ials_matches_the_gs(warehouse_gs):
    gs_life, gs_taken = warehouse_gs
    life, taken = _warehouse_ials("trained")
    # An item a neighbour takes lives ~4.8 steps in the GS; margin 10% (0.48 steps). The
    # shipped AIP gives ~4.9 (+2%); the 99.9% half-width at 200 episodes is ~0.27.
    assert_equivalent(gs_life, life, 0.10 * np.nanmean(gs_life), "life of items taken by neighbours")
    # Neighbours take ~19 items per episode (sd ~4.2); margin 15% (2.9 items), 99.9%
    # half-width ~1.4. (This count is not sensitive to the AIP: neighbours take nearly all
    # items on shared cells whatever the AIP; the item life above is.)
    assert_equivalent(gs_taken, taken, 0.15 * gs_taken.mean(), "items taken by neighbours per episode")


def test_warehouse_untrained_ials_does_not(warehouse_gs):
    gs_life, _ = warehouse_gs
    # Untrained: each neighbour stands on each shared cell w.p. 0.25 every step, so items
    # vanish too fast (~3.9 steps vs 4.8, half-width ~0.23); the empirical marginal P(u)
    # (F-IALS) ignores that neighbours walk *to* items, so they vanish far too slowly (~21).
    life, _ = _warehouse_ials("untrained")
    assert_different(gs_life, life, 0.10 * np.nanmean(gs_life), "untrained: life of items")
    life_m, _ = _warehouse_ials("marginal")
    assert_different(gs_life, life_m, 0.10 * np.nanmean(gs_life), "marginal: life of items")


# ------------------------------------------------------------------------------ traffic

TR, TLS = "traffic_grid_v0", "tls_12"
E_GS_TR, E_IALS_TR = 6, 32


def _traffic_ials(predictor, seed=5):
    """Per-episode (inflow per lane and step, occupancy of the 36 cells) in the IALS."""
    venv = make_ials_vec_env(TR, TLS, n_envs=E_IALS_TR, predictor=predictor, seed=seed)
    try:
        rng = np.random.default_rng(seed)
        occ = [venv.reset()[:, :36]]
        entries = []
        for t in range(300):
            obs = venv.step(rng.integers(2, size=E_IALS_TR))[0]
            # Cars that actually entered (an insertion the lane cannot take is dropped), the
            # LS's counterpart of the GS's influence bits.
            entries.append(venv.ls.last_entries.copy())
            if t < 299:
                occ.append(obs[:, :36])
    finally:
        venv.close()
    return np.stack(entries, 1).mean((1, 2)), np.stack(occ, 1).mean((1, 2))


@pytest.fixture(scope="module")
def traffic_gs():
    data = collect(TR, TLS, steps=E_GS_TR * 300, seed=5, progress=False)
    return data.influences.mean((1, 2)), data.dsets["dset"].mean((1, 2))


def test_traffic_ials_inflow_and_occupancy(traffic_gs):
    gs_in, gs_occ = traffic_gs
    tr_in, tr_occ = _traffic_ials("trained")
    un_in, un_occ = _traffic_ials("untrained")
    # Inflow into the region, cars that entered per lane and step: ~0.069 in the GS
    # (episode sd ~0.007), shipped AIP ~0.063 (-0.006), untrained far above (a random
    # network samples about 0.5 per lane; blocked insertions are dropped). Margin 0.02;
    # with 6 GS and 32 IALS episodes the 99.9% half-width is ~0.009.
    assert_equivalent(gs_in, tr_in, 0.02, "trained: inflow per lane")
    assert_different(gs_in, un_in, 0.0, "untrained: inflow per lane")
    assert un_in.mean() > gs_in.mean()
    # Occupancy of the 36 observed cells: even with the right inflow the LS holds fewer cars
    # than the GS (no spill-back from downstream lanes), so only compare gaps: the trained
    # AIP's occupancy is closer to the GS's than the untrained one's, which is too high.
    assert abs(tr_occ.mean() - gs_occ.mean()) < abs(un_occ.mean() - gs_occ.mean())
    assert_different(gs_occ, un_occ, 0.0, "untrained: occupancy")
    assert un_occ.mean() > gs_occ.mean()


def test_traffic_ials_env_checker():
    from gymnasium.utils.env_checker import check_env

    env = make_ials(TR, TLS, predictor="untrained", seed=0)
    try:
        check_env(env, skip_render_check=True)
        obs, _ = env.reset(seed=1)
        assert obs.shape == (40,)
        for t in range(300):
            obs, r, term, trunc, info = env.step(t % 2)
            assert not term and trunc == (t == 299)
    finally:
        env.close()
