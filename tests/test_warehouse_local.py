"""The warehouse local simulator, and its fidelity to the global simulator."""

import numpy as np
import pytest

from ials_zoo.core.domains import get_domain
from ials_zoo.warehouse import regions as R
from ials_zoo.warehouse.env import parallel_env
from ials_zoo.warehouse.local import WarehouseLocalSimulator


@pytest.mark.parametrize("agent,lifetime", [("robot_20", None), ("robot_20", 8), ("robot_0", None)])
def test_ls_replays_gs_region_exactly(agent, lifetime):
    """Start the LS from the GS region's state, then drive it with the learner's actions, the
    GS's true u_t and the GS's item-appearance draws: obs, rewards and d-sets must agree at
    every step of whole episodes, without ever re-synchronising."""
    gs = parallel_env(learners=[agent], item_probability=0.1, item_lifetime=lifetime)
    ls = WarehouseLocalSimulator(agent, n_envs=1, item_probability=0.1, item_lifetime=lifetime)
    rng = np.random.default_rng(0)
    non_none = positive = 0
    for episode in range(3):
        obs, infos = gs.reset(seed=episode)
        ls.reset(seed=99)
        pos, ages = gs.get_region_state(agent)
        ls.set_state([pos], ages[None])
        ls_obs, ls_dsets = ls.observe()
        np.testing.assert_array_equal(ls_obs[0], obs[agent])
        np.testing.assert_array_equal(ls_dsets["dset"][0], infos[agent]["dset"])
        while gs.agents:
            action = int(rng.integers(4))
            obs, rew, _, _, infos = gs.step({agent: action})
            u = infos[agent]["influence"]
            new_items = gs.get_region_state(agent)[1] == 1  # age 1 = appeared this step
            ls_obs, ls_rew, ls_dsets = ls.step(np.array([action]), u[None], new_items=new_items[None])
            np.testing.assert_array_equal(ls_obs[0], obs[agent])
            assert ls_rew[0] == rew[agent]
            np.testing.assert_array_equal(ls_dsets["dset"][0], infos[agent]["dset"])
            np.testing.assert_array_equal(ls_dsets["full"][0], infos[agent]["dset_full"])
            np.testing.assert_array_equal(ls.get_state()[1][0], gs.get_region_state(agent)[1])
            non_none += int((u != R.NONE).sum())
            positive += rew[agent] > 0
    assert non_none > 10 and positive > 3  # the replay did exercise both mechanisms


def test_ls_shapes_and_dtypes():
    ls = get_domain("warehouse_v0").local_simulator("robot_20", n_envs=5)
    obs, dsets = ls.reset(seed=0)
    assert obs.shape == (5, 37) and obs.dtype == np.float32
    assert dsets["dset"].shape == (5, 24) and dsets["dset"].dtype == np.uint8
    assert dsets["full"].shape == (5, 37) and dsets["full"].dtype == np.uint8
    assert (obs[:, R.CENTRE] == 1).all()
    obs, rew, dsets = ls.step(np.zeros(5, np.int64), np.full((5, 4), 3))
    assert rew.shape == (5,) and obs.shape == (5, 37)
    assert ls.observation_space.contains(obs[0])


def test_ls_influence_removes_items_and_own_robot_collects():
    ls = WarehouseLocalSimulator(n_envs=3, item_probability=0.0)
    ls.reset(seed=0)
    ages = np.zeros((3, 12), np.int64)
    ages[:, 1] = 4  # right side, middle cell
    ages[:, 9] = 2  # above side, left cell
    ls.set_state([13, 13, 12], ages)  # (2,3), (2,3), centre
    u = np.array([[3, 3, 3, 3], [1, 3, 3, 0], [3, 3, 3, 0]])
    obs, rew, dsets = ls.step(np.array([3, 3, 0]), u)
    np.testing.assert_allclose(rew, [1.0, 1.0, 0.0])
    items = dsets["dset"][:, :12]
    assert items[:, 1].tolist() == [0, 0, 1]  # collected, collected (both credited), aged
    assert items[:, 9].tolist() == [1, 0, 0]  # neighbour above on its cell 0 took it
    assert dsets["dset"][:, 12 + 1].tolist() == [1, 1, 0]
    assert ls.get_state()[1][2, 1] == 5


def test_ls_seeding_and_item_rate():
    a = WarehouseLocalSimulator(n_envs=64)
    b = WarehouseLocalSimulator(n_envs=64)
    acts = np.random.default_rng(0).integers(0, 4, size=(100, 64))
    infl = np.full((64, 4), 3)
    a.reset(seed=1)
    b.reset(seed=1)
    new = trials = 0
    for t in range(100):
        oa, ra, _ = a.step(acts[t], infl)
        ob, rb, _ = b.step(acts[t], infl)
        np.testing.assert_array_equal(oa, ob)
        np.testing.assert_array_equal(ra, rb)
        ages = a.get_state()[1]
        new += np.count_nonzero(ages == 1)
        trials += ages.size - np.count_nonzero(ages >= 2)
    sd = np.sqrt(trials * 0.02 * 0.98)
    assert abs(new - 0.02 * trials) < 4 * sd


def test_ls_item_lifetime():
    ls = WarehouseLocalSimulator(n_envs=4, item_probability=0.3, item_lifetime=8)
    ls.reset(seed=0)
    prev = ls.get_state()[1]
    vanished = 0
    for t in range(60):
        ls.step(np.full(4, t % 2), np.full((4, 4), 3))  # pacing between inner cells
        ages = ls.get_state()[1]
        gone = (prev > 0) & (ages <= 1)
        assert (prev[gone] == 8).all()
        vanished += gone.sum()
        prev = ages
    assert vanished > 20


@pytest.mark.parametrize(
    "actions,influences,exc,match",
    [
        (np.zeros(3, np.int64), np.full((2, 4), 3), ValueError, "actions must have shape"),
        (np.zeros((2, 2), np.int64), np.full((2, 4), 3), ValueError, "actions must have shape"),
        (np.zeros(2, np.int64), np.full((2, 3), 3), ValueError, "influences must have shape"),
        (np.zeros(2, np.int64), np.full(8, 3), ValueError, "influences must have shape"),
        (np.zeros(2, np.int64), np.full((2, 4), 4), ValueError, "influences must be in 0..3"),
        (np.zeros(2, np.int64), np.full((2, 4), -1), ValueError, "influences must be in 0..3"),
        (np.zeros(2, np.int64), np.full((2, 4), 3.0), TypeError, "influences must be ints"),
        (np.full(2, 1.5), np.full((2, 4), 3), TypeError, "actions must be ints"),
        (np.array([0, 4]), np.full((2, 4), 3), ValueError, "actions must be in 0..3"),
    ],
)
def test_ls_bad_input(actions, influences, exc, match):
    ls = WarehouseLocalSimulator(n_envs=2)
    ls.reset(seed=0)
    with pytest.raises(exc, match=match):
        ls.step(actions, influences)


def test_ls_accepts_column_actions():
    ls = WarehouseLocalSimulator(n_envs=2)
    ls.reset(seed=0)
    ls.step(np.array([[0], [1]]), np.full((2, 4), 3))
    assert ls.get_state()[0].tolist() == [7, 17]


def test_ls_bad_options():
    with pytest.raises(ValueError, match="n_envs"):
        WarehouseLocalSimulator(n_envs=0)
    with pytest.raises(ValueError, match="robot_77"):
        WarehouseLocalSimulator("robot_77")
    with pytest.raises(TypeError, match="colour"):
        WarehouseLocalSimulator(colour=1)
    ls = WarehouseLocalSimulator(n_envs=2)
    ls.reset()
    with pytest.raises(ValueError, match="new_items"):
        ls.step(np.zeros(2, np.int64), np.full((2, 4), 3), new_items=np.zeros((2, 12)))
    with pytest.raises(ValueError, match="positions"):
        ls.set_state([0, 12], np.zeros((2, 12), np.int64))


def test_region_factories_accept_gs_options():
    domain = get_domain("warehouse_v0")
    gs_options = {"learners": ["robot_20"], "render_mode": "ansi", "scripted_learners": False,
                  "item_lifetime": 8, "robots": (4, 6)}
    ls = domain.local_simulator("robot_20", n_envs=2, **gs_options)
    assert ls.item_lifetime == 8
    assert domain.region_spec("robot_20", **gs_options) == ls.region
    assert ls.region == domain.parallel_env(**gs_options).region_spec("robot_20")
    assert len(domain.possible_agents(**gs_options)) == 24
    with pytest.raises(TypeError, match="colour"):
        domain.region_spec("robot_20", colour=1)
    with pytest.raises(TypeError, match="colour"):
        domain.possible_agents(colour=1)
