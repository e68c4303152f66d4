"""The warehouse global simulator (warehouse_v0, SPEC §1)."""

import numpy as np
import pytest
from pettingzoo.test import api_test

from ials_zoo.core.domains import get_domain
from ials_zoo.warehouse import regions as R
from ials_zoo.warehouse.env import WarehouseEnv, env, parallel_env

# robot_20 is robot (3, 2) of the 6 x 6 layout; its neighbours on each side:
NEIGHBOURS_OF_20 = {0: "robot_21", 1: "robot_26", 2: "robot_19", 3: "robot_14"}


# ----------------------------------------------------------------------------- API


def test_aec_api_with_several_learners():
    # the generic API, seed and render checks run for every domain in test_domain_contract.py
    api_test(env(learners=["robot_0", "robot_20"], max_cycles=20), num_cycles=30)


def test_domain_registration_defaults():
    domain = get_domain("warehouse_v0")
    assert domain.possible_agents() == [f"robot_{i}" for i in range(36)]
    gs = domain.parallel_env(learners=["robot_20"])
    assert gs.possible_agents == ["robot_20"]
    ls = domain.local_simulator("robot_20", n_envs=3)
    assert ls.n_envs == 3
    spec = domain.region_spec("robot_20")
    assert spec == gs.region_spec("robot_20") == ls.region
    assert spec.n_sources == 4 and spec.influence_classes == (4, 4, 4, 4)
    assert spec.dset_size("dset") == 24 and spec.dset_size("full") == 37
    assert domain.episode_length == 100 and domain.frame_stack == 8
    assert domain.default_agents == ("robot_20",)


@pytest.mark.parametrize("max_cycles", [100, 7])
def test_truncation_exactly_at_max_cycles(max_cycles):
    gs = parallel_env(learners=["robot_3", "robot_20"], max_cycles=max_cycles)
    gs.reset(seed=0)
    for t in range(1, max_cycles + 1):
        assert gs.agents == ["robot_3", "robot_20"]
        _, _, term, trunc, _ = gs.step({a: t % 4 for a in gs.agents})
        assert not any(term.values())
        assert all(trunc.values()) == (t == max_cycles)
        assert any(trunc.values()) == (t == max_cycles)
    assert gs.agents == []
    with pytest.raises(RuntimeError, match="reset"):
        gs.step({})


def test_infos_contract():
    gs = parallel_env(learners=["robot_0", "robot_20"])
    obs, infos = gs.reset(seed=1)
    for a in gs.agents:
        assert gs.observation_space(a).contains(obs[a])
        assert infos[a]["dset"].dtype == np.uint8 and infos[a]["dset"].shape == (24,)
        assert infos[a]["dset_full"].dtype == np.uint8 and infos[a]["dset_full"].shape == (37,)
        np.testing.assert_array_equal(infos[a]["dset_full"], obs[a])
        np.testing.assert_array_equal(infos[a]["dset"][:12], obs[a][25:])
    obs, _, _, _, infos = gs.step({"robot_0": 0, "robot_20": 1})
    for a in gs.agents:
        u = infos[a]["influence"]
        assert u.dtype == np.int64 and u.shape == (4,) and ((0 <= u) & (u <= 3)).all()
        np.testing.assert_array_equal(infos[a]["dset_full"], obs[a])
    # robot_0 is in the top-left corner of the floor: no neighbour above or to the left.
    assert infos["robot_0"]["influence"][2] == R.NONE
    assert infos["robot_0"]["influence"][3] == R.NONE


def test_render_modes():
    gs = parallel_env(learners=["robot_20"], render_mode="rgb_array")
    gs.reset(seed=0)
    gs.step({"robot_20": 0})
    img = gs.render()
    assert img.dtype == np.uint8 and img.shape == (25 * 12, 25 * 12, 3)
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 5
    gs = parallel_env(learners=["robot_4"], render_mode="ansi", robots=(2, 3))
    gs.reset(seed=0)
    text = gs.render()
    lines = text.splitlines()
    assert isinstance(text, str) and len(lines) == 1 + 9
    assert all(len(line) == 13 for line in lines[1:])
    assert sum(line.count("R") + line.count("L") for line in lines[1:]) == 6
    assert "".join(lines[1:]).count("L") == 1


def test_save_gif(tmp_path):
    from ials_zoo.viewer import record_episode, save_gif

    gs = parallel_env(robots=(2, 2), max_cycles=5, render_mode="rgb_array")
    frames = record_episode(gs, seed=0)
    assert len(frames) == 6
    path = tmp_path / "episode.gif"
    save_gif(frames, path)
    assert path.read_bytes()[:4] == b"GIF8"
    assert [p.name for p in tmp_path.iterdir()] == ["episode.gif"]


# ----------------------------------------------------------------------------- dynamics


def test_robots_stay_in_region_and_off_corners():
    gs = parallel_env(learners=[f"robot_{i}" for i in range(0, 36, 2)], max_cycles=400)
    rng = np.random.default_rng(0)
    gs.reset(seed=0)
    prev = gs._pos.copy()
    origin = gs._origin
    seen_shelf = 0
    while gs.agents:
        gs.step({a: int(rng.integers(4)) for a in gs.agents})
        pos = gs._pos
        assert not np.isin(pos, R.CORNERS).any()
        floor = gs.robot_positions()
        assert ((floor >= origin) & (floor <= origin + 4)).all()
        moved = np.abs(prev // 5 - pos // 5) + np.abs(prev % 5 - pos % 5)
        assert (moved <= 1).all()
        # From a shelf cell the only move is back inward (to an inner cell).
        from_shelf = R.SHELF_INDEX[prev] >= 0
        seen_shelf += from_shelf.sum()
        left = from_shelf & (pos != prev)
        assert (R.SHELF_INDEX[pos[left]] == -1).all()
        prev = pos.copy()
    assert seen_shelf > 100


@pytest.mark.parametrize("p", [0.02, 0.1])
def test_item_appearance_rate(p):
    gs = parallel_env(learners=["robot_20"], item_probability=p, max_cycles=300)
    gs.reset(seed=5)
    new = trials = 0
    while gs.agents:
        gs.step({"robot_20": 0})
        ages = gs._ages[:-1]
        new += np.count_nonzero(ages == 1)
        trials += ages.size - np.count_nonzero(ages >= 2)  # cells empty before appearance
    sd = np.sqrt(trials * p * (1 - p))
    assert abs(new - trials * p) < 4 * sd, (new, trials * p)


def test_scripted_robots_head_for_oldest_item():
    gs = parallel_env(learners=["robot_0"])
    gs.reset(seed=0)
    rng = np.random.default_rng(3)
    inner_or_shelf = [p for p in range(25) if p not in R.CORNERS]
    for i in range(1, 36):
        ages = np.where(rng.random(12) < 0.4, rng.integers(1, 30, size=12), 0)
        gs.set_region_state(f"robot_{i}", position=int(rng.choice(inner_or_shelf)), item_ages=ages)
    before = [gs.get_region_state(f"robot_{i}") for i in range(36)]
    gs.step({"robot_0": 0})
    checked = 0
    for i in range(1, 36):
        pos, ages = before[i]
        new_pos, _ = gs.get_region_state(f"robot_{i}")
        if ages.max() == 0:
            assert new_pos != pos  # a random *move*
            continue
        target = R.ITEM_POS[int(np.argmax(ages))]  # oldest, ties to the lowest bit
        if pos == target:
            assert new_pos == pos  # stays and collects
        else:
            assert R.DIST[new_pos, target] == R.DIST[pos, target] - 1
        checked += 1
    assert checked > 20


def test_scripted_robot_walks_to_oldest_and_collects():
    gs = parallel_env(learners=["robot_0"], item_probability=0.0)
    gs.reset(seed=0)
    ages = np.zeros(12, dtype=np.int64)
    ages[7], ages[0], ages[10] = 9, 5, 9  # (2,0) is the oldest (ties go to the lower bit)
    gs.set_region_state("robot_20", position=R.CENTRE, item_ages=ages)
    gs.step({"robot_0": 0})
    assert gs.get_region_state("robot_20")[0] == 2 * 5 + 1
    gs.step({"robot_0": 0})
    pos, ages_after = gs.get_region_state("robot_20")
    assert pos == 2 * 5 + 0
    assert ages_after[7] == 0
    assert gs.episode_returns[20] == 1.0


def _quiet_world(p=0.0, learners=("robot_20",)):
    """All robots at their centres, no items: nobody can reach a shelf in one step."""
    gs = parallel_env(learners=list(learners), item_probability=p)
    gs.reset(seed=0)
    for i in range(36):
        gs.set_region_state(f"robot_{i}", position=R.CENTRE, item_ages=np.zeros(12, np.int64))
    return gs


@pytest.mark.parametrize("own_age,other_age,expected", [(6, 3, 1.0), (3, 6, 0.5), (4, 4, 1.0)])
def test_collect_reward_is_age_over_max_age(own_age, other_age, expected):
    gs = _quiet_world()
    ages = np.zeros(12, dtype=np.int64)
    ages[1], ages[7] = own_age, other_age  # (2,4) right side, (2,0) left side
    gs.set_region_state("robot_20", position=2 * 5 + 3, item_ages=ages)
    _, rew, _, _, infos = gs.step({"robot_20": 3})
    assert rew["robot_20"] == pytest.approx(expected)
    assert infos["robot_20"]["dset"][1] == 0  # collected
    assert infos["robot_20"]["dset"][12 + 1] == 1  # robot stands on item cell 1
    assert gs.items_collected == 1
    _, rew, _, _, _ = gs.step({"robot_20": 3})  # illegal on a shelf: stays, nothing left
    assert rew["robot_20"] == 0.0
    assert gs.get_region_state("robot_20")[0] == 2 * 5 + 4


def test_simultaneous_arrival_credits_both():
    gs = _quiet_world(learners=("robot_20", "robot_21"))
    ages = np.zeros(12, dtype=np.int64)
    ages[1] = 4  # robot_20's (2,4) is robot_21's (2,0), its item bit 7
    ages[4] = 8  # robot_20's bottom cell: robot_20's oldest item is another one
    gs.set_region_state("robot_20", position=2 * 5 + 3, item_ages=ages)
    gs.set_region_state("robot_21", position=2 * 5 + 1)
    assert gs.get_region_state("robot_21")[1][7] == 4
    _, rew, _, _, infos = gs.step({"robot_20": 3, "robot_21": 2})
    assert rew == {"robot_20": 0.5, "robot_21": 1.0}
    assert gs.items_collected == 1
    assert infos["robot_20"]["influence"].tolist() == [1, 3, 3, 3]
    assert infos["robot_21"]["influence"].tolist() == [3, 3, 1, 3]


@pytest.mark.parametrize("side", [0, 1, 2, 3])
@pytest.mark.parametrize("k", [0, 2])
def test_neighbour_on_shared_cell_sets_influence_and_removes_item(side, k):
    gs = _quiet_world()
    neighbour = NEIGHBOURS_OF_20[side]
    their_bit = 3 * R.opposite(side) + k
    their_cell = R.ITEM_POS[their_bit]
    inward = next(int(R.MOVE[their_cell, a]) for a in range(4) if R.LEGAL[their_cell, a])
    ages = np.zeros(12, dtype=np.int64)
    ages[their_bit] = 5
    gs.set_region_state(neighbour, position=inward, item_ages=ages)
    mine = gs.get_region_state("robot_20")[1]
    assert mine[3 * side + k] == 5 and mine.sum() == 5  # the same, shared item
    _, rew, _, _, infos = gs.step({"robot_20": 0})  # up: to an inner cell
    expected = [R.NONE] * 4
    expected[side] = k
    assert infos["robot_20"]["influence"].tolist() == expected
    assert infos["robot_20"]["dset"][3 * side + k] == 0  # the neighbour took the item
    assert infos["robot_20"]["dset"][12:].sum() == 0
    assert rew["robot_20"] == 0.0
    # Next step the neighbour (no item left) steps back inward: influence back to "none".
    _, _, _, _, infos = gs.step({"robot_20": 1})
    assert infos["robot_20"]["influence"][side] == R.NONE


def test_seeding_is_reproducible():
    def run(seed):
        gs = parallel_env(learners=["robot_20", "robot_7"], max_cycles=50)
        obs, _ = gs.reset(seed=seed)
        out = [obs["robot_20"].copy()]
        t = 0
        while gs.agents:
            obs, rew, _, _, infos = gs.step({a: t % 4 for a in gs.agents})
            out += [obs["robot_20"], obs["robot_7"], [rew["robot_20"]], infos["robot_7"]["influence"]]
            t += 1
        return np.concatenate([np.asarray(x, dtype=np.float64).ravel() for x in out]), gs._ages.copy()

    a, ages_a = run(11)
    b, ages_b = run(11)
    c, ages_c = run(12)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(ages_a, ages_b)
    assert not np.array_equal(ages_a, ages_c)


def test_reset_without_seed_continues_the_stream():
    gs = parallel_env(learners=["robot_20"])
    gs.reset(seed=3)
    first = gs._ages.copy()
    gs.reset()
    assert not np.array_equal(first, gs._ages)


def test_item_lifetime_items_vanish_after_exactly_n_steps():
    # One robot alone (no neighbours), pacing between inner cells: nobody collects anything.
    gs = parallel_env(robots=(1, 1), item_probability=0.3, item_lifetime=8, max_cycles=100)
    gs.reset(seed=0)
    prev = gs.get_region_state("robot_0")[1]
    vanished = 0
    for t in range(100):
        _, _, _, _, infos = gs.step({"robot_0": t % 2})  # up, down, up, ...
        ages = gs.get_region_state("robot_0")[1]
        assert ages.max() <= 8
        gone = (prev > 0) & ((ages == 0) | (ages == 1))
        assert (prev[gone] == 8).all()  # visible in exactly 8 observations
        vanished += gone.sum()
        assert ((ages == prev + 1) | ~(prev > 0) | gone).all()
        prev = ages
    assert vanished > 20


def test_items_live_forever_without_lifetime():
    gs = parallel_env(robots=(1, 1), item_probability=1.0, max_cycles=30)
    gs.reset(seed=0)
    for t in range(30):
        gs.step({"robot_0": t % 2})
        assert (gs.get_region_state("robot_0")[1] == t + 2).all()


def test_scripted_learners_ignore_actions():
    # Two fully scripted worlds with the same seed: whatever the "learners" ask for, the
    # scripted controller drives them, so both worlds stay identical.
    a = parallel_env(learners=["robot_20"], scripted_learners=True)
    b = parallel_env(learners=["robot_20", "robot_35"], scripted_learners=True)
    a.reset(seed=4)
    b.reset(seed=4)
    rewards = 0.0
    for t in range(60):
        _, rew_a, _, _, infos = a.step({"robot_20": t % 4})
        _, rew_b, _, _, _ = b.step({"robot_20": (t + 1) % 4, "robot_35": 1})
        assert "influence" in infos["robot_20"]
        assert rew_a["robot_20"] == rew_b["robot_20"]
        np.testing.assert_array_equal(a._pos, b._pos)
        np.testing.assert_array_equal(a._ages, b._ages)
        rewards += rew_a["robot_20"]
    assert rewards > 0  # the scripted controller collects items
    a.step({})  # actions may be left out
    with pytest.raises(ValueError, match="robot_3"):
        a.step({"robot_3": 0})


# ----------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "kwargs,exc,match",
    [
        ({"learners": ["robot_36"]}, ValueError, "robot_36"),
        ({"learners": ["bob"]}, ValueError, "bob"),
        ({"learners": ["robot_01"]}, ValueError, "robot_01"),
        ({"learners": "robot_1"}, TypeError, "learners"),
        ({"learners": []}, ValueError, "learners"),
        ({"learners": ["robot_1", "robot_1"]}, ValueError, "duplicates"),
        ({"robots": (0, 6)}, ValueError, "robots"),
        ({"robots": (6,)}, ValueError, "robots"),
        ({"robots": (2.0, 3)}, ValueError, "robots"),
        ({"item_probability": 1.5}, ValueError, "item_probability"),
        ({"item_probability": "0.1"}, TypeError, "item_probability"),
        ({"max_cycles": 0}, ValueError, "max_cycles"),
        ({"max_cycles": 10.0}, TypeError, "max_cycles"),
        ({"item_lifetime": 0}, ValueError, "item_lifetime"),
        ({"render_mode": "window"}, ValueError, "render_mode"),
        ({"scripted_learners": "yes"}, TypeError, "scripted_learners"),
        ({"colour": "red"}, TypeError, "colour"),
    ],
)
def test_bad_options(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        WarehouseEnv(**kwargs)


@pytest.mark.parametrize(
    "actions,exc,match",
    [
        ({"robot_20": 1, "robot_3": 0}, ValueError, "robot_3"),
        ({"robot_20": 1, "robot_4": 0, "nobody": 1}, ValueError, "nobody"),
        ({"robot_20": 1}, ValueError, "missing.*robot_4"),
        ({"robot_20": 1.5, "robot_4": 0}, TypeError, "robot_20.*float"),
        ({"robot_20": 1.0, "robot_4": 0}, TypeError, "robot_20"),
        ({"robot_20": np.array([1, 2]), "robot_4": 0}, TypeError, "robot_20.*shape"),
        ({"robot_20": 4, "robot_4": 0}, ValueError, "robot_20.*range"),
        ({"robot_20": 1, "robot_4": -1}, ValueError, "robot_4.*range"),
        ({"robot_20": True, "robot_4": 0}, TypeError, "robot_20.*bool"),
        ({"robot_20": "1", "robot_4": 0}, TypeError, "robot_20"),
        ([1, 2], TypeError, "dict"),
    ],
)
def test_bad_actions(actions, exc, match):
    gs = parallel_env(learners=["robot_4", "robot_20"])
    gs.reset(seed=0)
    with pytest.raises(exc, match=match):
        gs.step(actions)


def test_accepted_action_types():
    gs = parallel_env(learners=["robot_4", "robot_20"])
    gs.reset(seed=0)
    gs.step({"robot_20": np.int64(1), "robot_4": np.array(2)})
    gs.step({"robot_20": 3, "robot_4": np.uint8(0)})


def test_region_spec_bad_agent():
    with pytest.raises(ValueError, match="robot_40"):
        R.region_spec("robot_40")
    with pytest.raises(ValueError, match="robot_4"):
        R.region_spec("robot_4", robots=(2, 2))
    with pytest.raises(ValueError, match="unknown agent"):
        parallel_env().observation_space("robot_99")


def test_nearest_item_rule_walks_to_the_nearest_item_and_its_joint_score_loop_is_the_protocols():
    from ials_zoo.evaluation import evaluate_joint
    from ials_zoo.warehouse import regions as R
    from ials_zoo.warehouse.rules import nearest_item, score_joint

    obs = np.zeros(R.OBS_SIZE)
    obs[R.CENTRE] = 1  # at (2, 2); items on the right side's (1, 4) and the above side's (0, 2)
    obs[R.N_CELLS + 0] = obs[R.N_CELLS + 10] = 1
    assert nearest_item(obs) == 0  # up: (0, 2) is 2 moves away, (1, 4) 3
    obs[R.N_CELLS + 10] = 0
    assert nearest_item(obs) in (0, 3)  # towards (1, 4): up or right
    # with every robot scripted, the loop scores what the protocol's joint evaluation scores
    mean, _, _ = score_joint(3, rule=None, robots=[2, 2])
    assert mean == pytest.approx(evaluate_joint("warehouse_v0", "scripted", episodes=3, robots=[2, 2]).mean)
    rule, _, _ = score_joint(3, robots=[2, 2])
    assert rule > evaluate_joint("warehouse_v0", "random", episodes=3, robots=[2, 2]).mean


def test_the_memory_rule_walks_to_the_item_it_saw_first_and_forgets_at_each_episode():
    from ials_zoo.evaluation import load_policy
    from ials_zoo.warehouse import regions as R
    from ials_zoo.warehouse.rules import OldestSeenItem, nearest_item_centred, score_joint, toward_centre

    def observe(position, *item_bits):
        obs = np.zeros(R.OBS_SIZE)
        obs[position] = 1
        obs[[R.N_CELLS + b for b in item_bits]] = 1
        return obs

    far, near = 2, 10  # from the centre: (3, 4) is 3 moves away (down first), (0, 2) 2 (up)
    rule = OldestSeenItem()
    assert rule(observe(R.CENTRE, far)) == 1  # the only item
    assert rule(observe(R.CENTRE, far, near)) == 1  # the nearer newcomer is younger
    assert rule(observe(R.CENTRE, near)) == 0  # the old one was taken
    assert rule(observe(R.CENTRE, near, far)) == 0  # far reappeared: a new item, younger
    assert rule(observe(R.CENTRE + R.SIZE)) == toward_centre(R.CENTRE + R.SIZE) == 0  # empty: back up to the centre
    assert nearest_item_centred(observe(R.CENTRE - 1)) == 3  # empty: right, to the centre
    rule.reset(0)
    rule(observe(R.CENTRE, near))
    assert rule(observe(R.CENTRE, near, far)) == 0  # nothing remembered across episodes
    # the evaluator resets a rule with memory at each episode: scores do not depend on history
    policy = load_policy(OldestSeenItem())
    rule_state = policy.fn
    rule_state(observe(R.CENTRE, far))
    policy.reset(7)
    assert (rule_state._first_seen == -1).all() and rule_state._step == 0
    once, _, _ = score_joint(2, rule=OldestSeenItem, robots=[2, 2])
    again, _, _ = score_joint(2, rule=OldestSeenItem, robots=[2, 2])
    assert once == again
