"""traffic_grid_v0 global simulator on real SUMO: API, SPEC §2 dynamics, libsumo safety."""

import os
import signal
import time

import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_seed_test

from ials_zoo.core.domains import get_domain
from ials_zoo.sumo.lease import SimulationBusyError, SimulationError, WorkerDiedError
from ials_zoo.traffic import network
from ials_zoo.traffic.env import TrafficGridEnv, parallel_env
from ials_zoo.traffic.env import env as aec_env


@pytest.fixture
def gs():
    """A 3x3 grid with the centre learning, in-process; closed after the test."""
    envs = []

    def make(**kw):
        kw.setdefault("grid", (3, 3))
        if kw["grid"] == (3, 3):
            kw.setdefault("learners", ["tls_4"])
        e = TrafficGridEnv(**kw)
        envs.append(e)
        return e

    yield make
    for e in envs:
        e.close()


def _lane_ids(e, k):
    return [x + "_0" for x in network.incoming_edges(e.grid, e.learner_index[k])]


# ----------------------------------------------------------------------------- PettingZoo API


def test_parallel_seed_two_live_envs():
    made = []

    def fn():
        made.append(parallel_env(grid=(2, 2), max_cycles=20))
        return made[-1]

    parallel_seed_test(fn, num_cycles=20)
    # both were alive at once, so the auto backend put the second one in a worker
    assert sorted(e.backend for e in made) == ["inprocess", "worker"]


def test_aec_api():
    e = aec_env(grid=(2, 2), max_cycles=10)
    try:
        api_test(e, num_cycles=15)
    finally:
        e.close()


def test_spaces_and_region_spec(gs):
    e = gs()
    a = "tls_4"
    assert e.observation_space(a).shape == (40,)
    assert e.action_space(a).n == 2
    spec = e.region_spec(a)
    assert spec == get_domain("traffic_grid_v0").region_spec(a, grid=(3, 3))
    assert spec.dset_size("dset") == 36 and spec.dset_size("full") == 40
    assert spec.influence_classes == (2, 2, 2, 2)
    obs, infos = e.reset(seed=3)
    assert infos[a]["dset"].shape == (36,) and infos[a]["dset"].dtype == np.uint8
    assert np.array_equal(infos[a]["dset_full"], obs[a].astype(np.uint8))
    _, _, _, _, infos = e.step({a: 0})
    assert infos[a]["influence"].dtype == np.int64 and infos[a]["influence"].shape == (4,)


# ----------------------------------------------------------------------------- SPEC §2


def test_network_shape(gs):
    e = gs(grid=(3, 4), learners=["tls_5"])
    e.reset(seed=0)
    q = e.sumo_query
    edges = [x for x in q("edge", "getIDList") if not x.startswith(":")]
    rows, cols = 3, 4
    inner = 2 * (rows * (cols - 1) + cols * (rows - 1))
    fringe = 2 * 2 * (rows + cols)
    assert len(edges) == inner + fringe
    for ed in edges:
        assert q("edge", "getLaneNumber", ed) == 1
        assert q("lane", "getLength", ed + "_0") == pytest.approx(100.0)
        assert q("lane", "getMaxSpeed", ed + "_0") == pytest.approx(10.0)
    # every intersection is a traffic light with 12 links (3 turns x 4 approaches)
    assert sorted(q("trafficlight", "getIDList")) == sorted(f"tls_{i}" for i in range(12))
    assert len(q("trafficlight", "getRedYellowGreenState", "tls_5")) == 12
    # learners are driven by state (SUMO's "online" program), the others are actuated
    assert q("trafficlight", "getProgram", "tls_5") == "online"
    assert q("trafficlight", "getProgram", "tls_0") == "actuated"
    logic = [x for x in q("trafficlight", "getAllProgramLogics", "tls_0")
             if x.programID == "actuated"][0]  # fmt: skip
    assert [(p.duration, p.minDur, p.maxDur) for p in logic.phases] == [
        (31, 8, 45), (6, 3, 6), (31, 8, 45), (6, 3, 6)
    ]
    assert [p.state for p in logic.phases] == e.files.meta["states"]["tls_0"]
    assert float(q("trafficlight", "getParameter", "tls_0", "max-gap")) == 3.0
    assert float(q("trafficlight", "getParameter", "tls_0", "detector-gap")) == 0.8
    # vehicles: IDM, minGap 2.5, decel 7.5, departing at 10 m/s
    assert q("vehicletype", "getMinGap", "car") == 2.5
    assert q("vehicletype", "getDecel", "car") == 7.5
    assert q("vehicletype", "getMaxSpeed", "car") == 10.0
    assert 'carFollowModel="IDM"' in open(e.files.routes).read()


@pytest.mark.parametrize("internal_links", [True, False])
def test_occupancy_reward_influence_match_sumo(gs, internal_links):
    """Observation cells, reward and influence bits agree with direct SUMO queries."""
    e = gs(grid=(3, 3), learners=["tls_4", "tls_0"], internal_links=internal_links)
    e.reset(seed=5)
    junction_lanes = [x for x in e.sumo_query("lane", "getIDList") if x.startswith(":")]
    assert bool(junction_lanes) == internal_links
    rng = np.random.default_rng(0)
    prev = {a: [set() for _ in range(4)] for a in e.agents}
    n_entries = n_occ = 0
    for t in range(120):
        obs, rew, _, _, infos = e.step({a: int(rng.random() < 0.1) for a in e.agents})
        for k, a in enumerate(e.possible_agents):
            cells = np.zeros(36, np.uint8)
            speeds = []
            bits = np.zeros(4, np.int64)
            for j, lane in enumerate(_lane_ids(e, k)):
                ids = set(e.sumo_query("lane", "getLastStepVehicleIDs", lane))
                for v in ids:
                    dist = 100.0 - e.sumo_query("vehicle", "getLanePosition", v)
                    if dist < 90.0:
                        cells[9 * j + int(dist / 10)] = 1
                    speeds.append(e.sumo_query("vehicle", "getSpeed", v))
                bits[j] = bool(ids - prev[a][j])
                prev[a][j] = ids
            assert np.array_equal(infos[a]["dset"], cells), t
            assert np.array_equal(obs[a][:36], cells)
            assert rew[a] == pytest.approx(np.mean(speeds) / 10 if speeds else 0.0, abs=1e-6)
            assert np.array_equal(infos[a]["influence"], bits), t
            n_entries += bits.sum()
            n_occ += cells.sum()
    assert n_entries > 10 and n_occ > 10  # the checks above saw real traffic


def test_fringe_departures_count_as_entries(gs):
    # tls_0's northern and western lanes are fringe entries: cars depart on them
    e = gs(grid=(2, 2), learners=["tls_0"])
    e.reset(seed=1)
    seen = np.zeros(4, np.int64)
    departed = 0
    for _ in range(60):
        _, _, _, _, infos = e.step({"tls_0": 0})
        seen += infos["tls_0"]["influence"]
        for v in e.sumo_query("simulation", "getDepartedIDList"):
            departed += 1
            assert e.sumo_query("vehicle", "getSpeed", v) == 10.0  # departSpeed 10
            assert e.sumo_query("vehicle", "getRoadID", v).split("__")[0] in (
                "top_0", "top_1", "left_0", "left_1", "bottom_0", "bottom_1",
                "right_0", "right_1",
            )  # fmt: skip
    # 8 fringe entries at 0.1 per step for 60 steps: 48 expected
    assert 25 <= departed <= 75
    assert seen[0] > 0 and seen[3] > 0  # N and W: departures from the boundary
    # about 0.1 per step on a fringe entry
    assert 1 <= seen[0] <= 20 and 1 <= seen[3] <= 20


def test_yellow_interval_ignores_actions(gs):
    e = gs()
    obs, _ = e.reset(seed=0)
    a = "tls_4"
    light = lambda o: int(np.argmax(o[a][36:]))
    state = lambda: e.sumo_query("trafficlight", "getRedYellowGreenState", a)
    ns_green, ns_yellow, ew_green, _ = e.files.meta["states"][a]
    assert light(obs) == 0 and state() == ns_green
    seen = []
    for _ in range(3):  # switch, then keep asking to switch during the yellow
        obs, *_ = e.step({a: 1})
        seen.append((light(obs), e.sumo_query("simulation", "getTime")))
    # SUMO ran yellow for 3 s; the 2 actions seen during it were ignored
    assert [s[0] for s in seen] == [1, 1, 2]
    assert state() == ew_green
    for _ in range(10):
        obs, *_ = e.step({a: 0})
        assert light(obs) == 2 and state() == ew_green
    obs, *_ = e.step({a: 1})
    assert light(obs) == 3


def test_scripted_learners_ignore_actions(gs):
    runs = []
    for act in (0, 1):
        e = gs(grid=(2, 2), learners=["tls_0", "tls_3"], scripted_learners=True)
        e.reset(seed=7)
        traj = []
        for _ in range(50):
            obs, rew, *_ = e.step({a: act for a in e.agents})
            traj.append((obs["tls_0"].copy(), rew["tls_3"]))
        e.close()
        runs.append(traj)
    for (o1, r1), (o2, r2) in zip(*runs):
        assert np.array_equal(o1, o2) and r1 == r2
    # the actuated program stays in its first green for at least its minimum of 8 s
    assert all(int(np.argmax(o[36:])) == 0 for o, _ in runs[0][:8])


def test_truncation_and_warmup(gs):
    e = gs(grid=(2, 2), max_cycles=5, warmup_steps=40)
    e.reset(seed=2)
    s = e.simulation_stats()
    assert s["time"] == 40 and s["vehicles"] > 0
    for t in range(5):
        _, _, term, trunc, _ = e.step({a: 0 for a in e.agents})
        assert not any(term.values())
        assert all(trunc.values()) == (t == 4)
    assert e.agents == []
    with pytest.raises(RuntimeError, match="reset"):
        e.step({})


def test_render(gs):
    e = gs(render_mode="rgb_array")
    e.reset(seed=0)
    for _ in range(30):
        e.step({"tls_4": 0})
    img = e.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    assert (img == (30, 60, 200)).all(axis=2).sum() >= 9  # at least one car dot
    e2 = gs(render_mode="ansi")
    e2.reset(seed=0)
    text = e2.render()
    assert isinstance(text, str) and "t=0" in text


def test_cache_dir_override_and_rebuild(tmp_path, monkeypatch):
    monkeypatch.setenv("IALS_ZOO_CACHE", str(tmp_path))
    f = network.build_grid((2, 3))
    assert str(f.directory).startswith(str(tmp_path))
    mtime = os.path.getmtime(f.net)
    assert network.build_grid((2, 3)).directory == f.directory
    assert os.path.getmtime(f.net) == mtime  # reused, not rebuilt
    assert network.build_grid((3, 2)).directory != f.directory
    import shutil

    shutil.rmtree(f.directory)
    g = network.build_grid((2, 3))
    assert g.directory == f.directory and os.path.exists(g.net)
    leftovers = [p for p in os.listdir(tmp_path / "traffic") if p.startswith(".")]
    assert leftovers == []


# ----------------------------------------------------------------------------- libsumo safety


def _run(e, seed, actions):
    obs, _ = e.reset(seed=seed)
    out = [obs]
    for acts in actions:
        o, r, _, _, i = e.step(acts)
        out.append((o, r, {a: v["influence"] for a, v in i.items()}))
    return out


def _same(x, y):
    if isinstance(x, dict):
        return x.keys() == y.keys() and all(_same(x[k], y[k]) for k in x)
    if isinstance(x, (tuple, list)):
        return len(x) == len(y) and all(_same(a, b) for a, b in zip(x, y))
    return np.array_equal(np.asarray(x), np.asarray(y))


def test_two_live_envs_are_independent_and_deterministic(gs):
    e1 = gs(grid=(2, 2), learners=["tls_0", "tls_1"])
    e2 = gs(grid=(2, 2), learners=["tls_0", "tls_1"])
    assert (e1.backend, e2.backend) == ("inprocess", "worker")
    rng = np.random.default_rng(1)
    acts = [{a: int(rng.random() < 0.2) for a in e1.possible_agents} for _ in range(60)]
    e1.reset(seed=11)
    e2.reset(seed=11)
    for a in acts[:30]:
        e1.step(a)
    assert e1.simulation_stats()["time"] == 30
    assert e2.simulation_stats()["time"] == 0  # stepping e1 left e2 alone
    r1 = _run(e1, 11, acts)
    r2 = _run(e2, 11, acts)
    assert _same(r1, r2)  # same seed + actions -> same trajectory, in both backends
    r3 = _run(e2, 12, acts)
    assert not _same(r1, r3)


def test_inprocess_second_env_fails_loudly_and_close_frees(gs):
    e1 = gs(grid=(2, 2))
    assert e1.backend == "inprocess"
    with pytest.raises(SimulationBusyError, match="one per process"):
        TrafficGridEnv(grid=(2, 2), backend="inprocess")
    e1.close()
    e3 = gs(grid=(2, 2), backend="inprocess")
    e3.reset(seed=0)
    e3.step({a: 0 for a in e3.agents})


def test_dropped_env_frees_its_simulation():
    import gc

    e = TrafficGridEnv(grid=(2, 2), backend="inprocess")
    e.reset(seed=0)
    del e
    gc.collect()
    e2 = TrafficGridEnv(grid=(2, 2), backend="inprocess")
    try:
        e2.reset(seed=0)
    finally:
        e2.close()


def test_killed_worker_raises_then_reset_recovers(gs):
    e = gs(grid=(2, 2), backend="worker")
    e.reset(seed=0)
    e.step({a: 0 for a in e.agents})
    os.kill(e._sim.worker_pid, signal.SIGKILL)
    t0 = time.monotonic()
    with pytest.raises(WorkerDiedError, match="died"):
        e.step({a: 0 for a in e.agents})
    assert time.monotonic() - t0 < 5
    obs, _ = e.reset(seed=0)
    assert set(obs) == set(e.possible_agents)
    e.step({a: 0 for a in e.agents})


@pytest.mark.parametrize("backend", ["inprocess", "worker"])
def test_sumo_errors_become_clear_exceptions(gs, backend):
    e = gs(grid=(2, 2), backend=backend)
    e.reset(seed=0)
    with pytest.raises(SimulationError, match="no_such_lane"):
        e.sumo_query("lane", "getLength", "no_such_lane")
    e.step({a: 0 for a in e.agents})  # the simulation is still usable


# ----------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "kwargs, exc, match",
    [
        ({"grid": (0, 5)}, ValueError, "grid"),
        ({"grid": (1, 1)}, ValueError, "grid"),
        ({"grid": (11, 3)}, ValueError, "grid"),
        ({"grid": (2.5, 3)}, TypeError, "int"),
        ({"grid": "55"}, ValueError, "pair"),
        ({"learners": ["tls_99"]}, ValueError, "tls_99"),
        ({"learners": ["robot_1"]}, ValueError, "robot_1"),
        ({"learners": ["tls_1", "tls_1"]}, ValueError, "duplicate"),
        ({"max_cycles": 0}, ValueError, "max_cycles"),
        ({"warmup_steps": -1}, ValueError, "warmup_steps"),
        ({"inflow_probability": 1.5}, ValueError, "inflow_probability"),
        ({"backend": "gpu"}, ValueError, "backend"),
        ({"render_mode": "window"}, ValueError, "render_mode"),
        ({"speed": 3}, TypeError, "speed"),
        ({"internal_links": "no"}, TypeError, "internal_links"),
        ({"scripted_learners": 1}, TypeError, "scripted_learners"),
    ],
)
def test_bad_options(kwargs, exc, match):
    kwargs.setdefault("grid", (2, 2))
    with pytest.raises(exc, match=match):
        TrafficGridEnv(**kwargs)


def test_bad_actions(gs):
    e = gs(grid=(2, 2), learners=["tls_0"])
    e.reset(seed=0)
    for acts, exc, match in [
        ({"tls_0": 2}, ValueError, "0 .keep. or 1"),
        ({"tls_0": -1}, ValueError, "0 .keep. or 1"),
        ({"tls_0": 1.0}, TypeError, "int"),
        ({"tls_0": "1"}, TypeError, "int"),
        ({"tls_0": None}, TypeError, "int"),
        ({"tls_0": 0, "tls_3": 0}, ValueError, "unknown agent"),
        ({}, ValueError, "missing"),
        ([0], TypeError, "dict"),
    ]:
        with pytest.raises(exc, match=match):
            e.step(acts)
    with pytest.raises(ValueError, match="unknown agent"):
        e.observation_space("tls_3")
    with pytest.raises(ValueError, match="unknown agent"):
        e.region_spec("nope")
    e.step({"tls_0": np.int64(1)})  # numpy ints are fine
