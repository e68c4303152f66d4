"""One junction's IALS on a real network (cologne1's light): the GS's region data, the local
simulator fed the GS's own influence sources, and an AIP trained on GS data that brings
vehicles into the region at the GS's rate."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import ials_zoo
from ials_zoo.core.domains import get_domain
from ials_zoo.core.region import DSET_KINDS, INFLUENCE_KEY
from ials_zoo.sumo_net.env import SumoNetEnv

NET, LIGHT = "cologne1", "GS_cluster_357187_359543"
OPTIONS = {"net": NET, "max_cycles": 120}  # 20 minutes of the map's hour
LS_OPTIONS = {**OPTIONS, "record_seconds": 1200}


@pytest.fixture(scope="module", autouse=True)
def own_cache(tmp_path_factory):
    """The entry tables and AIPs are cached in a folder of this module's own."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("IALS_ZOO_CACHE", str(tmp_path_factory.mktemp("cache")))
        yield


@pytest.fixture(scope="module")
def data():
    from ials_zoo.influence.dataset import collect

    return collect("sumo_net_v0", LIGHT, steps=1440, seed=0, gs_options=OPTIONS, progress=False)


def test_the_gs_reports_region_data_only_when_asked_with_the_layout_of_the_region_spec():
    domain = get_domain("sumo_net_v0")
    region = domain.region_spec(LIGHT, **OPTIONS)
    exits = [n for n in region.influence_names if n.startswith("exit:")]  # one per exit and decision
    assert len(exits) == 4 and region.influence_classes[-4:] == (2,) * 4 and region.influence_classes[0] == 3
    assert region.n_sources == 10 * ((region.n_sources - 4) // 10) + 4  # entries: per second of the decision
    env = SumoNetEnv(learners=[LIGHT], region_data=True, **OPTIONS)
    plain = SumoNetEnv(learners=[LIGHT], max_cycles=2, net=NET)
    try:
        assert env.region_spec(LIGHT) == region
        _, infos = env.reset(seed=0)
        assert not infos[LIGHT][INFLUENCE_KEY].any()  # nothing has entered before the first step
        entered = 0
        for _ in range(10):
            _, _, _, _, step_infos = env.step({LIGHT: 0})
            entered += int(step_infos[LIGHT][INFLUENCE_KEY].sum())
        for info in (infos[LIGHT], step_infos[LIGHT]):
            assert info[INFLUENCE_KEY].shape == (region.n_sources,) and info[INFLUENCE_KEY].dtype == np.int64
            assert info["dset"].shape == (region.dset_size("dset"),) and info["dset"].dtype == np.uint8
            assert info["dset_full"].shape == (region.dset_size("full"),)
        assert entered > 0
        _, infos = plain.reset(seed=0)
        assert infos == {LIGHT: {}}
    finally:
        env.close()
        plain.close()


def test_the_local_simulator_has_the_gs_spaces_and_region():
    domain = get_domain("sumo_net_v0")
    env = SumoNetEnv(learners=[LIGHT], **OPTIONS)
    ls = domain.local_simulator(LIGHT, n_envs=2, **LS_OPTIONS)
    try:
        assert ls.region == domain.region_spec(LIGHT, **OPTIONS)
        assert ls.observation_space == env.observation_space(LIGHT) and ls.action_space == env.action_space(LIGHT)
        obs, dsets = ls.reset(seed=0)
        assert obs.shape == (2, *ls.observation_space.shape)
        for kind in DSET_KINDS:
            assert dsets[kind].shape == (2, ls.region.dset_size(kind))
    finally:
        env.close()
        ls.close()


def test_fed_the_gs_influence_the_local_simulator_lets_the_same_vehicles_in_and_tracks_the_reward():
    """The LS inserts what the sources say (measured like the GS's), and its light's reward
    follows the GS's: the region replays its inflow, vehicles drawn from the GS's own entries."""
    env = SumoNetEnv(learners=[LIGHT], region_data=True, **OPTIONS)
    ls = get_domain("sumo_net_v0").local_simulator(LIGHT, measure_entries=True, **LS_OPTIONS)
    rng = np.random.default_rng(0)
    told = entered = 0
    gs_rewards, ls_rewards = [], []
    try:
        env.reset(seed=3)
        ls.reset(seed=3)
        while env.agents:
            a = int(rng.integers(env.action_space(LIGHT).n))
            _, rewards, _, _, infos = env.step({LIGHT: a})
            u = infos[LIGHT][INFLUENCE_KEY]
            _, ls_reward, _ = ls.step(np.array([a]), u[None])
            told, entered = told + int(u.sum()), entered + int(ls.last_entries.sum())
            gs_rewards.append(rewards[LIGHT])
            ls_rewards.append(float(ls_reward[0]))
    finally:
        env.close()
        ls.close()
    assert told > 300 and 0.95 * told <= entered <= told, (told, entered)  # measured 0.97
    gs_mean, ls_mean = np.mean(gs_rewards), np.mean(ls_rewards)
    assert abs(ls_mean - gs_mean) < 0.1 * abs(gs_mean), (gs_mean, ls_mean)  # measured 0.3%


def test_an_exit_the_sources_block_holds_its_vehicles_and_the_queue_backs_up():
    """An exit source set to blocked holds the region's end of that road: the local simulator
    measures it blocked (a vehicle halting there, as the GS defines it) nearly every second it
    is told so (per decision: blocked for at least half its seconds), never when free, and the
    light waits longer behind it."""
    ls = get_domain("sumo_net_v0").local_simulator(LIGHT, measure_entries=True, **LS_OPTIONS)
    is_exit = np.array([n.startswith("exit:") for n in ls.regions[0].influence_names])
    told, seen, waits = {}, {}, {}
    try:
        for blocked in (False, True):
            ls.reset(seed=0)
            rng = np.random.default_rng(1)
            told[blocked], seen[blocked], waits[blocked] = [], [], []
            for k in range(40):
                u = np.where(is_exit, int(blocked and k >= 10), rng.random(is_exit.size) < 0.05)
                _, reward, _ = ls.step(np.array([k % 2]), u[None].astype(np.int64))
                if k >= 10:
                    told[blocked].append(u[is_exit])
                    seen[blocked].append(ls.last_entries[0][is_exit])
                    waits[blocked].append(-float(reward[0]))
    finally:
        ls.close()
    assert np.mean(seen[False]) == 0
    assert np.mean(np.asarray(seen[True])[np.asarray(told[True]) == 1]) > 0.8, np.mean(seen[True])  # measured 0.91: an exit no vehicle reached yet is free
    assert np.mean(waits[True]) > 5 * np.mean(waits[False]), (np.mean(waits[True]), np.mean(waits[False]))  # 2.75, 0.03


def test_a_given_block_reads_blocked_and_one_that_lasts_is_a_gridlock_that_stays():
    """The d-set reads an exit given blocked as blocked now (as the GS reads a jam's queue),
    with how long it has lasted; a block given :data:`GRIDLOCK_DECISIONS` decisions in a row
    stays, whatever the sources say next (SUMO without teleports never clears a gridlock), and
    a shorter one ends when the sources free it."""
    from ials_zoo.sumo_net.island import GRIDLOCK_DECISIONS

    ls = get_domain("sumo_net_v0").local_simulator(LIGHT, **LS_OPTIONS)
    region = ls.regions[0]
    is_exit = np.array([n.startswith("exit:") for n in region.influence_names])
    names = region.dset_names["dset"]
    now = np.array([n.startswith("blocked_") for n in names])
    held = {n: np.array([x.startswith(f"held{n}_") for x in names]) for n in (1, 10)}
    try:
        for blocks in (GRIDLOCK_DECISIONS - 1, GRIDLOCK_DECISIONS):
            ls.reset(seed=0)
            for k in range(blocks + 3):
                u = np.where(is_exit, int(k < blocks), 0)[None].astype(np.int64)
                _, _, dsets = ls.step(np.array([k % 2]), u)
                d = dsets["dset"][0]
                if k == 0:
                    assert d[now].all() and d[held[1]].all() and not d[held[10]].any()
                if k == blocks:  # the sources free every exit
                    gridlock = blocks >= GRIDLOCK_DECISIONS
                    assert (d[held[1]] == gridlock).all() and (d[held[10]] == gridlock).all(), (blocks, d[held[1]])
                    assert not gridlock or d[now].all()
    finally:
        ls.close()


def test_make_ials_of_a_junction_passes_gymnasiums_checker():
    env = ials_zoo.make_ials("sumo_net_v0", LIGHT, predictor="untrained", seed=0, **{**LS_OPTIONS, "max_cycles": 20})
    try:
        check_env(env, skip_render_check=True)
        env.reset(seed=1)
        steps, done = 0, False
        while not done:
            _, _, term, trunc, info = env.step(env.action_space.sample())
            steps, done = steps + 1, term or trunc
        assert steps == 20 and info[INFLUENCE_KEY].shape == (env.region.n_sources,)
    finally:
        env.close()


def test_an_aip_trained_on_gs_data_brings_vehicles_at_the_gs_rate(data):
    """Cross-entropy below the data's marginal, and the IALS's region gets the GS's inflow, as
    with the GS's recorded entry frequencies (no training); a uniform AIP floods it. The light's
    random actions are seeded: the flood's inflow depends on them (unseeded: 1.03x to 1.55x)."""
    from ials_zoo.influence.train import train_predictor
    from ials_zoo.sumo_net.island import gs_marginal_predictors

    pred, report = train_predictor(data, arch="mlp", epochs=30, lr=3e-3, progress=False)
    ce = report["cross_entropy"]
    assert ce["trained"]["test"] < 1.02 * ce["marginal"]["test"] < ce["untrained"]["test"]
    is_entry = np.array([not n.startswith("exit:") for n in data.region.influence_names])  # vehicles, not blocks
    gs_rate = np.asarray(data.influences)[..., is_entry].sum() / data.n_steps
    gs_blocked = np.asarray(data.influences)[..., ~is_entry].mean()  # exits blocked, per exit and decision
    rates, blocked = {}, {}
    recorded = gs_marginal_predictors([LIGHT], **LS_OPTIONS)[LIGHT]
    for name, predictor in (("trained", pred), ("recorded", recorded), ("uniform", "uniform")):
        env = ials_zoo.make_ials("sumo_net_v0", LIGHT, predictor=predictor, seed=0, measure_entries=True,
                                 **LS_OPTIONS)
        entered = steps = 0
        blocks = []
        try:
            for episode in range(2):
                env.reset(seed=episode)
                env.action_space.seed(episode)
                done = False
                while not done:
                    *_, term, trunc, _ = env.step(env.action_space.sample())
                    entered += int(env.ls.last_entries[0][is_entry].sum())
                    blocks.append(env.ls.last_entries[0][~is_entry])
                    steps, done = steps + 1, term or trunc
        finally:
            env.close()
        rates[name], blocked[name] = entered / steps, float(np.mean(blocks))
    assert abs(rates["trained"] - gs_rate) < 0.1 * gs_rate, (rates, gs_rate)  # measured 1.01x
    assert abs(rates["recorded"] - gs_rate) < 0.1 * gs_rate, (rates, gs_rate)  # 0.96x (every exit free)
    assert abs(blocked["trained"] - gs_blocked) < 0.05, (blocked, gs_blocked)
    # a uniform AIP blocks every exit one decision in two (its flood of entries then jams against the blocks:
    # how many get in varied from 0.88x to 1.0x the GS's rate, so that is not checked)
    assert blocked["uniform"] > gs_blocked + 0.2, (blocked, gs_blocked)


def test_train_aip_of_every_junction_feeds_the_multi_agent_ials(tmp_path, capsys):
    """``train-aip --agent all`` on a network whose junctions have regions of their own sizes
    trains each AIP alone into one set, which drives every region of the multi-agent IALS: a
    PettingZoo ParallelEnv with the GS's agents and spaces."""
    from pettingzoo.test import parallel_api_test

    from ials_zoo.cli import main
    from ials_zoo.influence.files import load_predictor_set
    from ials_zoo.sumo_net.ials_env import IALSNetEnv

    out = tmp_path / "aips.pt"
    assert main(["train-aip", "--env", "sumo_net_v0", "--net", "cologne3", "--options", '{"max_cycles": 30}',
                 "--agent", "all", "--steps", "60", "--epochs", "2", "--out", str(out), "--no-progress"]) == 0
    said = capsys.readouterr().out
    assert said.index("60 GS steps (2 episodes) to collect, about") < said.index("wrote")  # an estimate first
    assert main(["train-aip", "--data", str(out), "--net", "cologne3", "--out", str(tmp_path / "x.pt")]) == 2
    assert "--net names a network to collect on" in capsys.readouterr().err
    aips = load_predictor_set(out, "sumo_net_v0")
    gs = SumoNetEnv(net="cologne3", max_cycles=20)
    assert sorted(aips) == sorted(gs.possible_agents)
    assert len({p.region.n_sources for p in aips.values()}) > 1  # regions of their own sizes
    env = ials_zoo.make_ials_parallel_env("sumo_net_v0", predictor=str(out), net="cologne3", max_cycles=20,
                                          record_seconds=600)
    assert isinstance(env, IALSNetEnv)
    try:
        assert env.possible_agents == gs.possible_agents
        for a in gs.possible_agents:
            assert env.observation_space(a) == gs.observation_space(a)
            assert env.action_space(a) == gs.action_space(a)
        parallel_api_test(env, num_cycles=20)
        _, infos = env.reset(seed=0)
        _, _, _, _, infos = env.step({a: 0 for a in env.agents})
        for a in env.possible_agents:
            assert infos[a][INFLUENCE_KEY].shape == (aips[a].region.n_sources,)
    finally:
        gs.close()
        env.close()
    one = ials_zoo.make_ials("sumo_net_v0", gs.possible_agents[1], predictor=str(out), net="cologne3", max_cycles=30,
                             record_seconds=600)  # a set file gives make_ials the light's member
    try:
        assert one.predictor.region == aips[gs.possible_agents[1]].region
    finally:
        one.close()


def test_without_an_aip_make_ials_names_the_command_that_trains_one(own_cache):
    with pytest.raises(FileNotFoundError, match=r"train-aip --env sumo_net_v0 --agent .* --options '\{\"net\": \"cologne1\"\}'"):
        ials_zoo.make_ials("sumo_net_v0", LIGHT, net=NET)


class _Seconds:
    """SUMO's answers over a few seconds, as ``_libsumo`` gives them (which vehicles are on which
    edge and where, alive, on which road): the watcher's bookkeeping alone, against a hand-made
    account. ``seconds``: per second, ``{vehicle: (road, lane position)}``."""

    def __init__(self, seconds):
        self.seconds, self.t = seconds, 0

    def edge_getLastStepVehicleIDs(self, edge):
        return [v for v, x in self.seconds[self.t].items() if x[0] == edge]

    def vehicle_getIDList(self):
        return list(self.seconds[self.t])

    def vehicle_getRoadID(self, vehicle):
        return self.seconds[self.t][vehicle][0]

    def vehicle_getLanePosition(self, vehicle):
        return self.seconds[self.t][vehicle][1]

    def vehicle_getSpeed(self, vehicle):
        return (self.seconds[self.t][vehicle] + (10.0,))[2]

    def edge_getLastStepHaltingNumber(self, edge):
        return sum(self.vehicle_getSpeed(v) < 0.1 for v in self.edge_getLastStepVehicleIDs(edge))


class _NoLanes:
    def lane_getLastStepVehicleIDs(self, lane):
        return []

    def vehicle_getLanePosition(self, vehicle):
        raise AssertionError("no vehicles")


def test_the_entry_watcher_counts_each_vehicle_once_where_it_came_in():
    from ials_zoo.sumo_net.influence import EntryWatcher, RegionLayout

    # the region begins 100 m into in_a (its entry offset) and at in_b's start
    layout = RegionLayout("J", sources=("in_a", "in_b"), edges=("in_a", "in_b", "out"), source_lanes=(), lanes=(),
                          entry_offsets=(100.0, 0.0), exits=(("out", 25.0),))
    seconds = [{"a": ("in_a", 150), "x": ("far", 0), "f": ("in_a", 50)},     # a comes in on in_a; f is not in yet
               {"a": (":J_0", 1), "b": ("in_b", 10), "c": ("in_b", 20), "f": ("in_a", 90), "g": ("out", 3, 0.0)},
               # a crosses the junction; b and c come in on in_b; g appears on out (inserted there), halting in
               # the region's part of it: the exit is blocked
               {"a": ("out", 5), "b": ("in_b", 20), "c": ("in_b", 30), "d": ("out", 9, 0.0), "f": ("in_a", 105)},
               # a goes on; g left; d appears past the light, halting in the region's part of out: blocked;
               # f passes the entry offset
               {"b": ("in_b", 30), "e": ("in_a", 100), "f": ("in_a", 115), "d": ("out", 30, 0.0)}]  # a and c
               # left (c vanished: it arrived); e comes in right at the offset; d halts past the exit: free
    raw = _Seconds(seconds)
    watcher = EntryWatcher([layout], decision=4)
    watcher.reset()
    for t in range(4):
        raw.t = t
        watcher.after_step(raw)
    np.testing.assert_array_equal(watcher.counts[0], [[1, 0, 0], [0, 2, 1], [1, 0, 1], [1, 0, 0]])
    np.testing.assert_array_equal(watcher.blocked[0][:, 0], [0, 1, 1, 0])
    # per second ("in_a", "in_b", "inside"), second-major, two or more is class 2; then the exit, blocked for
    # at least half the decision
    np.testing.assert_array_equal(watcher.influences()[0], [1, 0, 0, 0, 2, 1, 1, 0, 1, 1, 0, 0, 1])
    watcher.blocked[0][1] = 0  # blocked one second of four: free
    assert watcher.influences()[0][-1] == 0
    raw.t = 2
    watcher.measure_exits(raw)
    # the d-set ends with the exits' blocks now, then whether each block has lasted 1, 3 and 10 decisions
    assert watcher.dsets(_NoLanes())[0].tolist() == [1, 0, 0, 0]
    blocked, free = np.array([0] * 12 + [1]), np.array([0] * 13)
    lasted = []
    for u in [blocked, blocked, free, *[blocked] * 10]:
        watcher.end_decision([u])
        lasted.append(watcher.dsets(_NoLanes())[0][1:].tolist())
    assert lasted[:4] == [[1, 0, 0], [1, 0, 0], [0, 0, 0], [1, 0, 0]]  # a free decision ends the block
    assert lasted[5] == [1, 1, 0] and lasted[11] == [1, 1, 0] and lasted[12] == [1, 1, 1]
    watcher.reset()
    assert watcher.dsets(_NoLanes())[0].tolist() == [0, 0, 0, 0]


def test_the_bench_reports_every_light_s_ials_and_the_multi_agent_ials_against_the_gs(capsys):
    from ials_zoo.sumo_net.benchmark import run_bench

    rows = run_bench(("cologne1",), repeats=1, max_cycles=30)
    single = next(r for r in rows if "speedup" in r)
    multi = next(r for r in rows if "local_over_gs" in r)
    assert single["agents"] == multi["agents"] == 1 and single["gs_decisions_per_s"] > 0
    assert np.isfinite(single["speedup"]).all() and np.isfinite(multi["local_over_gs"]).all()
    assert np.isfinite(multi["array_over_gs"]).all()
    assert "one light's IALS decisions/s" in capsys.readouterr().out
