"""The array local simulator (ials_zoo.sumo_net.arrays) against SUMO and against plain
references: its signals keep SUMO's program time, its vehicles never overlap nor run a red
light, its d-sets are the loop reference's, and the IALS and DIALS run on it."""

from __future__ import annotations

import numpy as np
import pytest

from ials_zoo.errors import BadInput
from ials_zoo.sumo.lease import inprocess_available
from ials_zoo.sumo_net.arrays import ArraySim
from ials_zoo.sumo_net.arrays_core import ArrayNetCore
from ials_zoo.sumo_net.arrays_layout import RED, RegionArrays, vehicle_kinds
from ials_zoo.sumo_net.influence import CELL_METRES, CELLS, HELD_DECISIONS, region_layout
from ials_zoo.sumo_net.island import entry_tables
from ials_zoo.sumo_net.network import read_network
from ials_zoo.sumo_net.regions import regions_of
from ials_zoo.sumo_net.scenario import make_scenario


@pytest.fixture(scope="module")
def cologne8():
    return make_scenario(net="cologne8")


@pytest.mark.parametrize("net", ["cologne8", "ingolstadt21"])
def test_every_program_keeps_sumos_phase_every_second(net):
    """Every light of every region on its own program (a region's own and those past its exits):
    the arrays' phase index equals SUMO's at every one of 300 seconds from the map's begin (a
    phase counts from the step after it starts). ingolstadt21 begins at 57,600 s, mid-cycle for
    two of its lights (SUMO runs a program as if from time 0)."""
    if not inprocess_available():
        pytest.skip("another simulation holds this process's libsumo")
    import libsumo

    from ials_zoo.sumo.command import sumo_command

    scenario = make_scenario(net=net)
    regions = regions_of(scenario.net_file)
    arrays = RegionArrays(scenario.net_file, regions, scenario.yellow_seconds, driven=False, begin=scenario.begin)
    sim = ArraySim(arrays, vehicle_kinds(scenario.route_files), 1, [[] for _ in regions])
    lights = [x for _, x in arrays.signals.names]
    libsumo.start(sumo_command(0, net=scenario.net_file, routes=list(scenario.route_files))
                  + ["--begin", str(scenario.begin)])
    try:
        for second in range(300):
            libsumo.simulationStep()
            sim.advance()
            assert [int(x) for x in sim.phase[0]] == [libsumo.trafficlight.getPhase(x) for x in lights], second
    finally:
        libsumo.close()


def test_a_program_begins_where_sumo_has_it_at_the_first_second():
    """The position in a fixed program at a begin time: (begin - offset) mod cycle, as a phase and
    the seconds into it less one (hand-computed: 55 s into a 20/3/30/3/26/3 cycle is 2 s into
    phase 3, which SUMO counts from the next step)."""
    from ials_zoo.sumo_net.arrays_layout import program_position

    durations = [20.0, 3.0, 30.0, 3.0, 26.0, 3.0]
    assert program_position(durations, 0.0, 57600.0) == (3, 1.0)
    assert program_position(durations, 0.0, 0.0) == (0, -1.0)
    assert program_position(durations, 10.0, 85.0 * 3 + 10.0) == (0, -1.0)
    assert program_position(durations, -5.0, 48.0) == (3, -1.0)  # 53 s in: phase 3 starts


def _gaps_ok(sim: ArraySim) -> bool:
    v = sim.v
    idx = np.flatnonzero(v.alive)
    order = idx[np.lexsort((-v.pos[idx], v.lane[idx]))]
    same = v.lane[order][1:] == v.lane[order][:-1]
    space = (v.pos[order][:-1] - v.length[order][:-1]) - v.pos[order][1:]
    return bool(np.all(space[same] >= v.gap[order][1:][same] - 1e-9))


def test_vehicles_never_overlap_and_stop_at_a_red_line(cologne8):
    """Every entry of the GS's first 300 s into one region whose light is held red on every
    link: vehicles queue at the line (none past it, none overlapping), and on green they go."""
    light = "cluster_1098574052_1098574061_247379905"
    regions = {light: regions_of(cologne8.net_file)[light]}
    arrays = RegionArrays(cologne8.net_file, regions, cologne8.yellow_seconds, driven=[light])
    lanes = read_network(cologne8.net_file).light(light).lanes
    sim = ArraySim(arrays, vehicle_kinds(cologne8.route_files), 1, [lanes], patience=None)
    row = arrays.signals.names.index((0, light))
    first = arrays.signals.phase_start[row]  # the light's first green, shown red on every link and held
    green = arrays.signals.shows[first].copy()
    arrays.signals.shows[first] = RED
    sim.set_phase(0, row, 0)
    sim.elapsed[:] = -1e9
    tables = entry_tables(cologne8, [light])[light]
    rng = np.random.default_rng(0)
    incoming = {arrays.lane_of[0][x] for x in lanes}
    for second in range(300):
        for j, table in enumerate(tables):
            if table and rng.random() < 0.15:
                edges, lane, pos, vtype, factor = table[int(rng.integers(len(table)))]
                sim.enter(0, 0, edges, lane, pos, vtype, factor)
        sim.advance()
        assert _gaps_ok(sim), second
        v = sim.v
        on = v.alive & np.isin(v.lane, list(incoming))
        assert np.all(v.pos[on] <= sim.length[v.lane[on]] + 1e-9), second
    queued = int((sim.v.alive & np.isin(sim.v.lane, list(incoming))).sum())
    assert queued > 10  # a real queue formed
    arrays.signals.shows[first] = green  # the green again: the queue moves
    before = sim.inserted - int(sim.v.alive.sum())
    for _ in range(60):
        sim.advance()
        assert _gaps_ok(sim)
    assert sim.inserted - int(sim.v.alive.sum()) > before  # vehicles left the region


def test_entries_on_one_lane_of_two_that_lead_on_spread_once_it_queues(cologne8):
    """An entry a second, all on one lane of a two-lane first edge whose lanes both lead on, the
    light held red: the first stay on the lane they came in on, and once it holds
    ``ENTRY_PENALTY`` more vehicles per share (equal shares, uncalibrated) they take the other."""
    from ials_zoo.sumo_net.arrays import ENTRY_PENALTY

    light = "247379907"
    regions = {light: regions_of(cologne8.net_file)[light]}
    arrays = RegionArrays(cologne8.net_file, regions, cologne8.yellow_seconds, driven=[light])
    sim = ArraySim(arrays, vehicle_kinds(cologne8.route_files), 1, [[]], patience=None)
    row = arrays.signals.names.index((0, light))
    arrays.signals.shows[arrays.signals.phase_start[row]] = RED
    sim.set_phase(0, row, 0)
    sim.elapsed[:] = -1e9
    entries = [e for table in entry_tables(cologne8, [light])[light] for e in table]
    edges, came_in, _pos, vtype, factor = next(
        (edges, lane, pos, vtype, factor) for edges, lane, pos, vtype, factor in entries
        if (arrays.routes.lanes[arrays.routes.step_of(0, edges)] >= 0).sum() == 2)
    own, other = sorted(arrays.routes.lanes[arrays.routes.step_of(0, edges)][:2],
                        key=lambda x: arrays.lane_index[x] != came_in)
    share = arrays.lane_share[own]
    assert share == arrays.lane_share[other] == 0.5
    counts = []
    for _ in range(40):
        sim.enter(0, 0, edges, came_in, 0.0, vtype, factor)
        sim.advance()
        counts.append((int(sim._on_lane[own]), int(sim._on_lane[other])))
    assert counts[0] == (1, 0)  # both empty: it keeps its lane
    first_other = next(k for k, (_a, b) in enumerate(counts) if b)
    # (own + 1) / share > (0 + 1) / share + ENTRY_PENALTY first when own exceeds ENTRY_PENALTY * share
    assert counts[first_other - 1][0] == int(ENTRY_PENALTY * share) + 1
    assert abs(counts[-1][0] - counts[-1][1]) <= ENTRY_PENALTY * share + 1


def test_free_speed_is_the_highest_that_brakes_to_the_turns_speed_by_the_line():
    """Reference: a vehicle that drives ``free_speed`` now and then brakes at ``b`` each second
    (never below the target) is at most at the target in the second it passes the line, and
    0.05 m/s more now would pass it faster. Random distances, targets and decelerations."""
    from ials_zoo.sumo_net.arrays import free_speed

    def passing_speed(speed, dist, target, b):
        done = 0.0
        while done + speed <= dist + 1e-9:
            done, speed = done + speed, max(target, speed - b)
        return speed

    rng = np.random.default_rng(0)
    dist, target, b = rng.uniform(0, 150, 500), rng.uniform(1, 14, 500), rng.uniform(2, 7.5, 500)
    speed = free_speed(dist, target, b)
    for now, d, t, bb in zip(speed, dist, target, b):
        assert passing_speed(now, d, t, bb) <= t + 1e-9
        assert passing_speed(now + 0.05, d, t, bb) > t


def test_vehicles_cross_a_turn_no_faster_than_its_speed_limit():
    """ingolstadt21's light 243641585 on its own program, fed its GS entries: every vehicle that
    crosses onto its next lane does so no faster than the junction's internal lane allows it (its
    speed factor times the limit); most of its right turns are slower than their lane."""
    scenario = make_scenario(net="ingolstadt21")
    light = "243641585"
    arrays = RegionArrays(scenario.net_file, {light: regions_of(scenario.net_file)[light]}, scenario.yellow_seconds,
                          driven=False, begin=scenario.begin)
    import sumolib

    net = sumolib.net.readNet(scenario.net_file, withInternal=True)  # the reference: SUMO's own reading

    def limit(from_lane, to_lane):
        lane = net.getLane(arrays.lane_ids[from_lane].split("__", 1)[1])
        to = arrays.lane_ids[to_lane].split("__", 1)[1].rsplit("_", 1)[0]
        via = next(c.getViaLaneID() for c in lane.getOutgoing() if c.getTo().getID() == to)
        return net.getLane(via).getSpeed(), lane.getSpeed()

    sim = ArraySim(arrays, vehicle_kinds(scenario.route_files), 1, [[]], patience=None)
    crossed = []
    switch = sim._switch

    def recording(w, lanes, positions):
        for x, to in zip(w, lanes):
            turn, lane_speed = limit(sim.v.lane[x], to)
            crossed.append((sim.v.speed[x], turn * sim.v.factor[x], lane_speed * sim.v.factor[x]))
        switch(w, lanes, positions)

    sim._switch = recording
    tables, rng = entry_tables(scenario, [light])[light], np.random.default_rng(0)
    for _ in range(600):
        for table in tables:
            if table and rng.random() < 0.1:
                sim.enter(0, 0, *table[int(rng.integers(len(table)))])
        sim.advance()
    speed, turn, lane_limit = np.array(crossed).T
    assert np.all(speed <= turn + 1e-9)
    slower = turn < lane_limit
    assert slower.sum() > 20 and np.mean(speed[slower] > turn[slower] - 1.0) > 0.2  # they reach the limit


def _reference_dsets(core: ArrayNetCore, layouts: list) -> list[np.ndarray]:
    """The d-sets read vehicle by vehicle (the EntryWatcher's rule on the pool)."""
    v, n, out = core.sim.v, core.arrays.n_lanes, []
    told = core.plan[core.data.exit_pos] > 0
    for c in range(core.copies):
        for r, layout in enumerate(layouts):
            bits = np.zeros((len(layout.source_lanes), CELLS), np.uint8)
            offsets = layout.lane_offsets or (0.0,) * len(layout.source_lanes)
            for i, (lane, offset) in enumerate(zip(layout.source_lanes, offsets)):
                for x in np.flatnonzero(v.alive & (v.lane == c * n + core.arrays.lane_of[r][lane])):
                    k = int((v.pos[x] - offset) // CELL_METRES)
                    if 0 <= k < CELLS:
                        bits[i, k] = 1
            exits = np.flatnonzero(core.data.region_of_exit == r)
            now = []
            for e, (edge, leave) in zip(exits, layout.exits):
                lanes = [c * n + x for x in core.arrays.edge_lanes[r][edge]]
                halted = [x for x in np.flatnonzero(v.alive & np.isin(v.lane, lanes))
                          if v.speed[x] < 0.1 and v.pos[x] <= leave]
                now.append(int(told[c, e] or bool(halted)))
            held = [int(core.held[c, e] >= h) for e in exits for h in HELD_DECISIONS]
            out.append(np.concatenate([bits.reshape(-1), now, held]).astype(np.uint8))
    return out


def _every_region(scenario, copies: int):
    """The scenario's lights, the array core of every light's region in ``copies`` copies, and
    the regions' layouts."""
    lights = read_network(scenario.net_file).lights
    ids = [x.id for x in lights]
    tables = entry_tables(scenario, ids)
    core = ArrayNetCore(scenario.net_file, scenario.route_files, scenario.begin, scenario.decision_seconds,
                        scenario.yellow_seconds, ids, [x.lanes for x in lights], [tables[x] for x in ids], copies=copies)
    return lights, core, [region_layout(scenario.net_file, x) for x in ids]


def test_the_dsets_are_the_vehicle_by_vehicle_reference(cologne8):
    """Two copies of cologne8's every region, flooded with entries and with exits blocked at
    random: at every decision the batched d-sets equal the loop reference's."""
    lights, core, layouts = _every_region(cologne8, copies=2)
    rng = np.random.default_rng(1)
    out = core.reset(3)
    blocked_some = False
    for decision in range(25):
        dsets = out[3][1]
        expected = _reference_dsets(core, layouts)
        assert all(np.array_equal(a, b) for a, b in zip(dsets, expected)), decision
        blocked_some |= any(d[len(x.source_lanes) * CELLS:].any() for d, x in zip(dsets, layouts * 2))
        influences = []
        for k in range(2 * len(lights)):
            layout = layouts[k % len(lights)]
            entries = np.minimum(rng.integers(0, 3, size=cologne8.decision_seconds * len(layout.points)),
                                 rng.integers(0, 2, size=cologne8.decision_seconds * len(layout.points)) * 2)
            influences.append(np.concatenate([entries, rng.random(len(layout.exits)) < 0.3]).astype(np.int64))
        out = core.step([int(rng.integers(x.n_actions)) for _ in range(2) for x in lights], influences)
    assert core.sim.inserted > 200 and blocked_some


def test_the_pools_order_and_lane_counts_are_recomputed_references_every_second(cologne8):
    """The simulator keeps its vehicles sorted (lane, then front first) by merging only those
    that changed lane or came in, and counts the vehicles per lane as they move: every second,
    over two copies of every region flooded with entries and exits blocked, the order is a
    fresh sort's and the counts a fresh bincount's."""
    lights, core, layouts = _every_region(cologne8, copies=2)
    rng = np.random.default_rng(2)
    core.reset(4)
    sim, crossed = core.sim, 0
    for _ in range(20):
        influences = [np.concatenate([rng.integers(0, 2, size=cologne8.decision_seconds * len(x.points)),
                                      rng.random(len(x.exits)) < 0.2]).astype(np.int64) for x in layouts * 2]
        core.step([int(rng.integers(x.n_actions)) for _ in range(2) for x in lights], influences)
        v = sim.v
        assert np.array_equal(sim._on_lane, np.bincount(v.lane[v.alive], minlength=len(sim.length)))
        n = sim._sort_pool()
        assert v.alive[:n].all() and not v.alive[n:].any()
        assert np.array_equal(np.lexsort((-v.pos[:n], v.lane[:n])), np.arange(n))
        crossed = max(crossed, int((v.came[:n] >= 0).sum()))
    assert sim.inserted > 300 and crossed > 50  # many came in, many changed lanes


def test_the_ials_on_arrays_runs_without_sumo_and_leaves_the_lease_free():
    """IALSNetEnv(local="arrays") steps an episode slice in this process without taking the
    process's SUMO lease (a GS can still start here), with the SUMO regions' spaces and region data."""
    from ials_zoo.sumo_net.env import SumoNetEnv
    from ials_zoo.sumo_net.ials_env import IALSNetEnv

    env = IALSNetEnv(predictors="uniform", net="cologne3", local="arrays", max_cycles=12)
    try:
        assert inprocess_available()  # the arrays hold no simulation
        gs = SumoNetEnv(net="cologne3", backend="inprocess", fresh_process=False, max_cycles=2)
        gs.close()
        obs, infos = env.reset(seed=0)
        spec = env.region_spec(env.possible_agents[0])
        a = env.possible_agents[0]
        assert infos[a]["dset"].shape == (len(spec.dset_names["dset"]),)
        assert infos[a]["influence"].shape == (len(spec.influence_names),)
        total = 0.0
        while env.agents:
            obs, rewards, _, _, infos = env.step({x: 0 for x in env.agents})
            total += sum(rewards.values())
        assert total < 0  # vehicles came in and waited
    finally:
        env.close()
    with pytest.raises(BadInput, match="local"):
        IALSNetEnv(predictors="uniform", net="cologne3", local="cells")


def test_dials_copies_on_arrays_are_one_batch_and_reproducible():
    """GSVecEnv(simulator="ials", local="arrays"): every copy in one batch; the same seed gives
    the same observations and rewards, another seed others."""
    from ials_zoo.learners.gs_vec import GSVecEnv

    def run(seed):
        env = GSVecEnv("sumo_net_v0", None, 3, 0, seed=0, simulator="ials", predictor="uniform", net="cologne3",
                       local="arrays", max_cycles=20)
        try:
            assert env._local.batched is not None and not env._local.envs
            obs = [env.reset(seed=seed)]
            rng = np.random.default_rng(0)
            rewards, done = [], False
            while not done:
                o, r, done = env.step(rng.integers(2, size=(len(env.agents), 3)))
                obs.append(o)
                rewards.append(r)
            return np.stack(obs), np.stack(rewards)
        finally:
            env.close()

    a, b, c = run(5), run(5), run(6)
    assert a[0].shape[:3] == (21, 3, 3) and a[1].shape == (20, 3, 3)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert not np.array_equal(a[1], c[1])
    assert a[1].min() < 0


def test_sources_as_blocks_are_the_same_decisions_as_rows(cologne8):
    """step_blocks (DIALS's batch: a region's copies as one block) and step (the IALS env's
    rows, copy-major) given the same sources and seed make the same episode, bit for bit."""
    lights = read_network(cologne8.net_file).lights
    ids = [x.id for x in lights]
    tables = entry_tables(cologne8, ids)

    def core():
        return ArrayNetCore(cologne8.net_file, cologne8.route_files, cologne8.begin, cologne8.decision_seconds,
                            cologne8.yellow_seconds, ids, [x.lanes for x in lights], [tables[x] for x in ids], copies=3)

    rows, blocks = core(), core()
    blocks.as_blocks = True
    rows.reset(7)
    blocks.reset(7)
    layouts = [region_layout(cologne8.net_file, x) for x in ids]
    rng = np.random.default_rng(0)
    for _ in range(12):
        per_region = [np.concatenate([rng.integers(0, 2, size=(3, cologne8.decision_seconds * len(x.points))),
                                      rng.random((3, len(x.exits))) < 0.2], axis=1).astype(np.int64) for x in layouts]
        actions = [int(rng.integers(x.n_actions)) for _ in range(3) for x in lights]
        m1, p1, _, (_, dsets) = rows.step(actions, [per_region[k % len(ids)][k // len(ids)] for k in range(3 * len(ids))])
        m2, p2, _ = blocks.step_blocks(actions, per_region)
        assert np.array_equal(m1, m2) and np.array_equal(p1, p2)
        assert all(np.array_equal(dsets[c * len(ids) + r], b[c]) for r, b in enumerate(blocks.dset_blocks())
                   for c in range(3))
    assert rows.sim.inserted > 50


def test_a_grid_of_any_size_by_name_runs_on_the_gs_and_on_arrays():
    """sumo_net_v0(net="grid3x3"): nine lights of two greens, built at first use; the GS and the
    IALS on arrays step it; a size out of range is refused by name."""
    from ials_zoo.sumo_net.arrays_vec import ArrayIALSCopies
    from ials_zoo.sumo_net.env import SumoNetEnv

    scenario = make_scenario(net="grid3x3")
    lights = read_network(scenario.net_file).lights
    assert len(lights) == 9 and all(x.n_actions == 2 for x in lights)
    gs = SumoNetEnv(net="grid3x3", backend="auto", fresh_process=False, max_cycles=30)
    try:
        gs.reset(seed=0)
        while gs.agents:
            _, rewards, *_ = gs.step({a: 0 for a in gs.agents})
        assert min(rewards.values()) < 0  # one green only for 300 s: queues on the other roads
    finally:
        gs.close()
    ials = ArrayIALSCopies(None, "uniform", [0, 1], net="grid3x3", max_cycles=5)
    try:
        obs = ials.reset([0, 1])
        assert obs.shape == (9, 2, 20)
        for _ in range(5):
            obs, rewards, done = ials.step(np.zeros((9, 2), np.int64))
        assert done and rewards.shape == (9, 2)
    finally:
        ials.close()
    for bad in ("grid1x5", "grid21x2"):
        with pytest.raises(BadInput, match=bad):
            make_scenario(net=bad)


def test_copies_that_could_outgrow_memory_are_refused_before_any_work(cologne8):
    """The bound counts every lane jammed; a million copies of cologne8 exceed any machine
    here, and the error names the estimate and what to change."""
    from ials_zoo.sumo_net.arrays_core import memory_bound

    lights = read_network(cologne8.net_file).lights
    ids = [x.id for x in lights]
    arrays = RegionArrays(cologne8.net_file, {x: regions_of(cologne8.net_file)[x] for x in ids}, 3)
    assert memory_bound(arrays, 2) == 2 * memory_bound(arrays, 1) > 0
    with pytest.raises(BadInput, match="GiB.*fewer copies"):
        ArrayNetCore(cologne8.net_file, cologne8.route_files, cologne8.begin, 10, 3, ids, [x.lanes for x in lights],
                     [[] for _ in ids], copies=1_000_000)
