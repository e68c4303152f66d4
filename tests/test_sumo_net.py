"""sumo_net_v0: RESCO's maps and any SUMO network, checked against independent references:
RESCO's own delay loop (readXML.py, re-implemented here), plain SUMO, RESCO's signal
bookkeeping (traffic_signal.py's observe, re-implemented on libsumo getters), hand-computed
controller choices."""

import os
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from ials_zoo import sumo_net_v0
from ials_zoo.errors import BadInput
from ials_zoo.sumo.command import sumo_binary, sumo_command
from ials_zoo.sumo_net.controllers import Greedy, MaxPressure, run_episode
from ials_zoo.sumo_net.core import yellow_program
from ials_zoo.sumo_net.env import SumoNetEnv
from ials_zoo.sumo_net.metrics import episode_metrics
from ials_zoo.sumo_net.network import read_network
from ials_zoo.sumo_net.scenario import make_scenario
from ials_zoo.sumo_net.study import run_plain_sumo


def resco_delay_reference(tripinfo, route_file, end_time):
    """RESCO's readXML.py delay loop, as written there (one route file)."""
    root = ET.parse(tripinfo).getroot()
    num_trips, total, last_departure_time, last_depart_id = 0, 0.0, 0, ""
    for child in root:
        num_trips += 1
        total += float(child.attrib["timeLoss"]) + float(child.attrib["departDelay"])
        depart_time = float(child.attrib["depart"])
        if depart_time > last_departure_time:
            last_departure_time, last_depart_id = depart_time, child.attrib["id"]
    route = ET.parse(route_file).getroot()
    last_departure_time = None
    for child in route:
        if child.attrib.get("id") == last_depart_id:
            last_departure_time = float(child.attrib["depart"])
    never = [float(c.attrib["depart"]) for c in route if c.tag == "vehicle" and float(c.attrib["depart"]) > last_departure_time]
    total += float(np.sum(end_time - np.asarray(never)))
    return total / (num_trips + len(never))


def _plain_tripinfo(tmp_path, net, end=None, seed=0):
    s = make_scenario(net=net, end=end)
    trip = str(tmp_path / f"{net}.xml")
    cmd = sumo_command(seed, net=s.net_file, routes=s.route_files, extra=[
        "--begin", str(s.begin), "--end", str(s.end), "--time-to-teleport", "-1",
        "--tripinfo-output", trip, "--tripinfo-output.write-unfinished", "true"])
    cmd[0] = sumo_binary()
    subprocess.run(cmd, check=True, capture_output=True, timeout=600)
    return s, trip


@pytest.mark.parametrize("net", ["cologne1", "grid4x4"])  # <trip> and <vehicle> route files
def test_delay_is_rescos_on_two_maps(tmp_path, net):
    s, trip = _plain_tripinfo(tmp_path, net)
    ours = episode_metrics(trip, s.route_files, s.end)
    assert ours["delay"] == pytest.approx(resco_delay_reference(trip, s.route_files[0], s.end), rel=1e-12)
    assert ours["vehicles"] > 1000 and 0 < ours["delay"] < 200


def test_the_never_departed_penalty_reads_vehicles_only_as_resco_does(tmp_path):
    """A hand-made tripinfo and route file where 2 <vehicle>s and 1 <trip> never departed."""
    trip = tmp_path / "t.xml"
    trip.write_text('<tripinfos><tripinfo id="a" depart="0" departDelay="2" timeLoss="10" duration="50" '
                    'waitingTime="3" arrival="50"/><tripinfo id="b" depart="5" departDelay="0" timeLoss="4" '
                    'duration="30" waitingTime="1" arrival="-1"/></tripinfos>')
    routes = tmp_path / "r.rou.xml"
    routes.write_text('<routes><vehicle id="a" depart="0"/><trip id="b" depart="4"/><vehicle id="c" depart="40"/>'
                      '<trip id="d" depart="50"/><vehicle id="e" depart="60"/></routes>')
    m = episode_metrics(str(trip), [str(routes)], 100)
    assert m["delay"] == pytest.approx(resco_delay_reference(str(trip), str(routes), 100))
    assert m["delay"] == pytest.approx((12 + 4 + 60 + 40) / 4)
    assert m["delay_all"] == pytest.approx((12 + 4 + 60 + 50 + 40) / 5)
    assert m["throughput"] == 1 and m["vehicles"] == 2


def test_fixed_time_in_the_env_is_plain_sumo_exactly_episode_after_episode():
    """The env's own-program episode is the simulation a plain sumo process runs (the env
    observes without disturbing), every time: run_episode starts a fresh SUMO worker, because
    later libsumo simulations of one process drifted from it on <trip> routes (SUMO 1.28)."""
    plain = run_plain_sumo(3, net="cologne1")
    for _ in range(3):
        ours = run_episode("fixed", 3, net="cologne1")
        for key in ("delay", "trip_time", "waiting_time", "throughput", "vehicles"):
            assert ours[key] == plain[key], key


def test_vehicles_near_a_light_are_what_an_env_detecting_that_far_counts():
    """The greedy rule reads its 50 m wave from an env that detects at 200 m: at every decision
    it is the queue + approach of an env that detects at 50 m (RESCO's MAXWAVE env), lane by lane."""
    near, far = SumoNetEnv(net="cologne1", max_cycles=40), SumoNetEnv(net="cologne1", max_cycles=40,
                                                                      max_distance=50.0)
    try:
        near.reset(seed=4)
        far.reset(seed=4)
        tls = near.agents[0]
        rng = np.random.default_rng(0)
        counted = 0
        while near.agents:
            m = far.measures(tls)
            got = near.near_counts(tls, 50.0)
            np.testing.assert_array_equal(got, m["queue"] + m["approach"])
            assert (near.near_counts(tls, 1e6) >= got).all()
            counted += got.sum()
            act = {tls: int(rng.integers(near.action_space(tls).n))}
            near.step(act)
            far.step(act)
        assert counted > 20  # vehicles were there to count
    finally:
        near.close()
        far.close()


@pytest.mark.parametrize("program", ["fixed", "actuated"])
def test_scripted_learners_run_the_program_observed_and_rewarded(program):
    """``scripted_learners`` leaves every light on its program (the episode of learners=[]),
    while the learners are still observed and rewarded; their actions are ignored."""
    plain = SumoNetEnv(net="cologne1", max_cycles=30, learners=[])
    plain.reset(seed=2)
    plain.run_uncontrolled(actuated=program == "actuated")
    want = plain.episode_metrics()
    plain.close()
    env = SumoNetEnv(net="cologne1", max_cycles=30, scripted_learners=program)
    try:
        env.reset(seed=2)
        tls, total = env.agents[0], 0.0
        while env.agents:
            _, rewards, *_ = env.step({tls: env.action_space(tls).n - 1})
            total += rewards[tls]
        got = env.episode_metrics()
    finally:
        env.close()
    assert total < 0 and got["delay"] == want["delay"] and got["throughput"] == want["throughput"]
    with pytest.raises(BadInput, match="scripted_learners must be"):
        SumoNetEnv(net="cologne1", scripted_learners="greedy")


def test_one_env_repeats_an_episode_exactly_reset_after_reset():
    """Every episode in a fresh SUMO process (the default): the same seed, the same episode,
    however many episodes the env ran before (in one libsumo process they drifted)."""
    env = sumo_net_v0.parallel_env(net="cologne1", learners=[])
    try:
        runs, pids = [], []
        for _ in range(3):
            env.reset(seed=3)
            pids.append(env._sim.worker_pid)
            runs.append(env.run_uncontrolled())
    finally:
        env.close()
    assert runs[0] == runs[1] == runs[2] and len(set(pids)) == 3  # three processes
    with pytest.raises(BadInput, match="fresh_process"):
        sumo_net_v0.parallel_env(net="cologne1", backend="inprocess")


def test_an_episodes_tripinfo_is_read_when_asked_and_never_left_behind(tmp_path):
    """Training never asks for the metrics, so the tripinfo is read only by episode_metrics(),
    which gives RESCO's figures of the file SUMO wrote; an episode never asked about leaves no file."""
    env = sumo_net_v0.parallel_env(net="cologne1", end=25_500)  # 30 decisions
    episode = os.path.join(env._tmp, "tripinfo_{}.xml")
    try:
        for n in (1, 2):
            env.reset(seed=3)
            assert not os.path.exists(episode.format(n - 1))  # the last one, never asked about
            while env.agents:
                env.step({a: 0 for a in env.agents})
            assert os.path.exists(episode.format(n))  # SUMO wrote it; nobody read it
        shutil.copy(episode.format(2), tmp_path / "trip.xml")
        metrics = env.episode_metrics()
        assert os.listdir(env._tmp) == []  # read once, then removed
        assert metrics == env.episode_metrics()
        env.reset(seed=3)
        env.step({a: 0 for a in env.agents})
        env.reset(seed=3)  # the third episode, cut short
        assert os.listdir(env._tmp) == ["tripinfo_4.xml"]  # the fourth's, SUMO writing it
        while env.agents:
            env.step({a: 0 for a in env.agents})
    finally:
        env.close()
    with pytest.raises(RuntimeError, match="before close"):
        env.episode_metrics()  # its file went with the env
    s = env.scenario
    reference = episode_metrics(str(tmp_path / "trip.xml"), s.route_files, s.end)
    assert {k: metrics[k] for k in reference} == reference and metrics["queue"] > 0


class _RescoSignal:
    """RESCO's Signal.observe (traffic_signal.py) on libsumo getters, for comparison."""

    def __init__(self, env, lanes):
        self.env, self.lanes, self.waits, self.last = env, lanes, {}, None

    def observe(self, step_length, max_distance):
        q = self.env.sumo_query
        out, seen = [], set()
        for lane in self.lanes:
            m = {"queue": 0, "approach": 0, "total_wait": 0.0, "speed": 0.0}
            for v in q("lane", "getLastStepVehicleIDs", lane):
                path = q("vehicle", "getNextTLS", v)
                if not (len(path) > 0 and path[0][2] <= max_distance):
                    continue
                seen.add(v)
                if v in self.waits:
                    self.waits[v] += step_length
                elif q("vehicle", "getWaitingTime", v) > 0:
                    self.waits[v] = q("vehicle", "getWaitingTime", v)
                wait = self.waits.get(v, 0)
                if wait > 0:
                    m["total_wait"] += wait
                    m["queue"] += 1
                else:
                    m["approach"] += 1
                m["speed"] += q("vehicle", "getSpeed", v)
            out.append(m)
        if self.last is not None:
            for v in self.last - seen:
                self.waits.pop(v, None)
        self.last = seen
        return out


def test_observations_and_rewards_follow_rescos_bookkeeping():
    env = sumo_net_v0.parallel_env(net="cologne1", max_cycles=60)
    tls = env.possible_agents[0]
    ref = _RescoSignal(env, list(env.network.light(tls).lanes))
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=1)
    ref.observe(10, 200)
    busy = 0
    try:
        for _ in range(59):  # the 60th decision ends the episode and closes SUMO
            obs, rew, _, _, _ = env.step({tls: int(rng.integers(env.action_space(tls).n))})
            lanes = ref.observe(10, 200)
            phase = env.sumo_query("trafficlight", "getPhase", tls)
            want = np.array([[float(i == phase), m["approach"] / 28, m["total_wait"] / 28, m["queue"] / 28,
                              m["speed"] / 20 / 28] for i, m in enumerate(lanes)], np.float32).reshape(-1)
            np.testing.assert_allclose(obs[tls], want, rtol=1e-6, atol=1e-7)
            total = sum(m["total_wait"] for m in lanes)
            assert rew[tls] == pytest.approx(float(np.clip(-total / 224, -4, 4)))
            busy += total > 0
    finally:
        env.close()
    assert busy > 20  # the comparison saw waiting vehicles


@pytest.mark.parametrize("observation", ["drq_norm", "drq"])
def test_every_lights_observation_at_once_is_the_per_light_function_bit_for_bit(observation):
    """The env builds RESCO's tables for all lights in one pass: the same bits as the observation
    function applied light by light (the reference), the green's lane marker included."""
    from ials_zoo.sumo_net.mdp import OBSERVATIONS

    env = sumo_net_v0.parallel_env(net="cologne3", max_cycles=30, observation=observation)
    light_by_light = OBSERVATIONS[observation]
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=2)
    markers = 0
    try:
        while True:
            for a in env.possible_agents:
                want = light_by_light(env._light_measures(a), int(env._phases[env._index[a]]))
                assert obs[a].dtype == want.dtype and obs[a].shape == want.shape
                np.testing.assert_array_equal(obs[a], want)
                markers += int(want[0::5].sum())
            state = env.state()
            np.testing.assert_array_equal(state, np.concatenate([obs[a] for a in env.network.ids]))
            if not env.agents:
                break
            obs, *_ = env.step({a: int(rng.integers(env.action_space(a).n)) for a in env.agents})
    finally:
        env.close()
    assert markers > 30  # the comparison saw the lights' green markers


def test_yellows_are_rescos_and_a_change_of_green_ends_in_that_green():
    greens = ["GGrr", "rrGG", "GrGr"]
    yellows, index = yellow_program(greens, 3)
    # (0 -> 1): links 0 and 1 lose green; (0 -> 2): link 1; (1 -> 0): 2, 3; (1 -> 2): 3; (2 -> 0): 2; (2 -> 1): 0
    assert yellows == [(3, "yyrr"), (3, "Gyrr"), (3, "rryy"), (3, "rrGy"), (3, "Gryr"), (3, "yrGr")]
    assert index == {(0, 1): 3, (0, 2): 4, (1, 0): 5, (1, 2): 6, (2, 0): 7, (2, 1): 8}
    env = sumo_net_v0.parallel_env(net="ingolstadt1", max_cycles=5)
    tls = env.possible_agents[0]
    light = env.network.light(tls)
    env.reset(seed=0)
    try:
        assert [light.phases[i][0] for i in light.greens] == [38, 6, 37]
        for a in (2, 0, 2):
            env.step({tls: a})
            # greens 0 and 2 last 37-38 s in the file: still the chosen green 7 s after the yellow
            assert env.sumo_query("trafficlight", "getPhase", tls) == a
            assert env.sumo_query("trafficlight", "getRedYellowGreenState", tls) == light.green_states()[a]
        # green 1 lasts 6 s: as in RESCO (setPhase keeps the file's duration) it has moved on to
        # the next phase of the installed program, green 2, by the end of the decision
        env.step({tls: 1})
        assert env.sumo_query("trafficlight", "getPhase", tls) == 2
    finally:
        env.close()


class _Fake:
    """Just enough of an env for a controller: agents, network and measures."""

    def __init__(self, network, measures):
        self.network, self._m = network, measures
        self.agents = network.ids

    def measures(self, tls):
        return self._m[tls]

    def queues(self):
        return np.concatenate([self._m[x.id]["queue"] for x in self.network.lights])

    def near_all(self, distance):
        assert distance == 50.0  # MAXWAVE's own detection distance
        return np.concatenate([self._m[x.id]["queue"] + self._m[x.id]["approach"] for x in self.network.lights])


@pytest.mark.parametrize("net_name", ["cologne8", "grid4x4"])
def test_greedy_and_max_pressure_pick_what_a_hand_count_picks(net_name):
    """grid4x4 too: there 288 of 384 movements have downstream lanes, so the downstream queue's
    sign changes max pressure's choice (on cologne8 with these queues it never does)."""
    net = read_network(make_scenario(net=net_name).net_file)
    rng = np.random.default_rng(0)
    measures = {x.id: {"queue": rng.integers(0, 9, len(x.lanes)).astype(float),
                       "approach": rng.integers(0, 9, len(x.lanes)).astype(float)} for x in net.lights}
    fake = _Fake(net, measures)
    greedy, pressure = Greedy(net)(fake), MaxPressure(net)(fake)
    incoming = {lane: (x.id, k) for x in net.lights for k, lane in enumerate(x.lanes)}
    for x in net.lights:
        m = measures[x.id]
        waves = [sum(m["queue"][x.lanes.index(lane)] + m["approach"][x.lanes.index(lane)]
                     for lane in {i for i, o, k in x.links if x.green_states()[a][k] in "Gg"})
                 for a in range(x.n_actions)]
        assert greedy[x.id] == int(np.argmax(waves))
        assert pressure[x.id] == int(np.argmax(_hand_pressures(net, x, measures, incoming)[0]))
    assert len(set(greedy.values())) > 1 or len(set(pressure.values())) > 1


def _hand_pressures(net, x, measures, incoming):
    """Light ``x``'s greens' pressures and its own, counted by hand from every light's queues."""
    scores, downstream = [], set()
    q = measures[x.id]["queue"]
    for a in range(x.n_actions):
        moves = {}
        for i, o, k in x.links:
            if x.green_states()[a][k] in "Gg":
                moves.setdefault((net.lane_edges[i], net.lane_edges[o]), set()).add(i)
        score = 0.0
        for (_, out_edge), lanes in moves.items():
            score += sum(q[x.lanes.index(lane)] for lane in lanes)
            down = [lane for lane, edge in net.lane_edges.items() if edge == out_edge and lane in incoming]
            score -= sum(measures[incoming[lane][0]]["queue"][incoming[lane][1]] for lane in down)
            downstream.update(down)
        scores.append(score)
    own = q.sum() - sum(measures[incoming[lane][0]]["queue"][incoming[lane][1]] for lane in downstream)
    return scores, own


def test_wait_scaled_is_wait_norm_without_its_clip():
    from ials_zoo.sumo_net.mdp import wait_norm, wait_scaled

    small, large = np.zeros((3, 5)), np.zeros((3, 5))
    small[:, 1], large[:, 1] = [100.0, 50.0, 0.0], [900.0, 600.0, 300.0]
    assert wait_scaled(small, 0) == wait_norm(small, 0) == -150.0 / 224
    assert wait_norm(large, 0) == -4.0 and wait_scaled(large, 0) == -1800.0 / 224


def test_mplights_observation_and_pressure_reward_are_the_hand_count():
    """MPLight's observation (each green's pressure, then a one-hot of the current green) and
    RESCO's pressure reward, at every decision of a grid4x4 episode, against the hand count."""
    env = SumoNetEnv(net="grid4x4", max_cycles=25, observation="mplight", reward="pressure")
    try:
        obs, _ = env.reset(seed=1)
        net = env.network
        incoming = {lane: (x.id, k) for x in net.lights for k, lane in enumerate(x.lanes)}
        rng = np.random.default_rng(0)
        seen = 0.0
        while env.agents:
            acts = {a: int(rng.integers(env.action_space(a).n)) for a in env.agents}
            obs, rewards, *_ = env.step(acts)
            measures = {x.id: env.measures(x.id) for x in net.lights}
            for x in net.lights:
                scores, own = _hand_pressures(net, x, measures, incoming)
                n = x.n_actions
                assert obs[x.id].shape == env.observation_space(x.id).shape == (2 * n,)
                np.testing.assert_allclose(obs[x.id][:n], scores)
                assert obs[x.id][n:].sum() == 1 and obs[x.id][n + acts[x.id]] == 1  # a green lasts the decision here
                assert rewards[x.id] == -own
                seen += abs(own)
        assert seen > 50  # queues were there to count
    finally:
        env.close()
    with pytest.raises(BadInput, match="GS only"):
        from ials_zoo.sumo_net.local import LocalNetEnv

        LocalNetEnv(net="cologne1", observation="mplight")


def test_the_wave_observation_is_greedys_hand_count_and_greedy_is_its_argmax():
    """``wave``: each green's vehicles within 50 m on its served lanes (over 28), counted by hand
    from the env's per-light counts, then the one-hot of the current green; greedy's choice is the
    first half's argmax at every decision of a cologne8 episode."""
    env = SumoNetEnv(net="cologne8", max_cycles=40, observation="wave")
    greedy = Greedy(env.network)
    try:
        obs, _ = env.reset(seed=2)
        rng, seen, held = np.random.default_rng(0), 0.0, 0
        while env.agents:
            chosen = greedy(env)
            for x in env.network.lights:
                near, n = env.near_counts(x.id, 50.0), x.n_actions
                hand = [sum(near[x.lanes.index(lane)] for lane in x.served_lanes(a)) for a in range(n)]
                assert obs[x.id].shape == env.observation_space(x.id).shape == (2 * n,)
                np.testing.assert_allclose(obs[x.id][:n] * 28.0, hand, rtol=1e-6)
                assert chosen[x.id] == int(np.argmax(obs[x.id][:n]))
                seen += sum(hand)
            acts = {a: int(rng.integers(env.action_space(a).n)) for a in env.agents}
            obs, *_ = env.step(acts)
            for a in env.agents:  # mplight's one-hot (its test holds it to the action on grid4x4)
                n = env.action_space(a).n  # here a green shorter than the decision moves on: none or another
                assert obs[a][n:].sum() <= 1.0 and set(np.unique(obs[a][n:])) <= {0.0, 1.0}
                held += obs[a][n + acts[a]] == 1.0
        assert seen > 50 and held > 0.5 * 40 * len(env.possible_agents)  # vehicles to count, greens that held
    finally:
        env.close()
    with pytest.raises(BadInput, match="GS only"):
        from ials_zoo.sumo_net.local import LocalNetEnv

        LocalNetEnv(net="cologne1", observation="wave")


def test_drq_wave_is_drq_norm_then_wave_at_every_decision():
    """``drq_wave``: RESCO's drq_norm table, then the wave table, of the same decision."""
    envs = {k: SumoNetEnv(net="ingolstadt7", max_cycles=15, observation=k) for k in ("drq_wave", "drq_norm", "wave")}
    try:
        obs = {k: e.reset(seed=3)[0] for k, e in envs.items()}
        rng, counted = np.random.default_rng(1), 0.0
        while envs["drq_wave"].agents:
            for a in envs["drq_wave"].agents:
                both = obs["drq_wave"][a]
                assert both.shape == envs["drq_wave"].observation_space(a).shape
                np.testing.assert_array_equal(both, np.concatenate([obs["drq_norm"][a], obs["wave"][a]]))
            acts = {a: int(rng.integers(envs["wave"].action_space(a).n)) for a in envs["wave"].agents}
            obs = {k: e.step(acts)[0] for k, e in envs.items()}
            counted += sum(x[:envs["wave"].action_space(a).n].sum() for a, x in obs["wave"].items())
        assert counted > 0  # the waves were not all empty
    finally:
        for e in envs.values():
            e.close()


def test_rule_based_lights_beat_fixed_time_and_random_on_cologne1():
    delay = {c: run_episode(c, 0, net="cologne1")["delay"] for c in ("fixed", "greedy", "max_pressure", "random")}
    assert delay["greedy"] < 0.7 * delay["fixed"] and delay["max_pressure"] < 0.7 * delay["fixed"]
    assert delay["random"] > delay["fixed"]


def test_an_env_in_this_process_and_one_in_a_worker_match():
    a = sumo_net_v0.parallel_env(net="ingolstadt1", max_cycles=20, backend="auto", fresh_process=False)
    b = sumo_net_v0.parallel_env(net="ingolstadt1", max_cycles=20)
    try:
        assert a.backend == "inprocess" and b.backend == "worker"
        oa, _ = a.reset(seed=4)
        ob, _ = b.reset(seed=4)
        tls = a.possible_agents[0]
        for t in range(20):
            act = {tls: t % a.action_space(tls).n}
            oa, ra, *_ = a.step(act)
            ob, rb, *_ = b.step(act)
            np.testing.assert_array_equal(oa[tls], ob[tls])
            assert ra == rb
        assert a.episode_metrics() == b.episode_metrics()
    finally:
        a.close()
        b.close()


def _netgenerate(tmp_path, tls: bool):
    bin_dir = os.path.join(os.path.dirname(sumo_binary()))
    net = tmp_path / ("tls.net.xml" if tls else "plain.net.xml")
    cmd = [os.path.join(bin_dir, "netgenerate"), "--grid", "--grid.number", "3", "--grid.length", "100",
           "--no-turnarounds", "true", "-o", str(net), "--seed", "1"]
    if tls:
        cmd += ["--default-junction-type", "traffic_light"]
    subprocess.run(cmd, check=True, capture_output=True, timeout=120)
    return net


def test_bring_your_own_network(tmp_path):
    net = _netgenerate(tmp_path, tls=True)
    routes = tmp_path / "r.rou.xml"
    trips = "".join(f'<trip id="t{i}" depart="{i * 3}" from="A0B0" to="B2C2"/>' for i in range(80))
    routes.write_text(f"<routes>{trips}</routes>")
    env = sumo_net_v0.parallel_env(net_file=str(net), route_files=[str(routes)], end=400)
    try:
        assert env.possible_agents == read_network(str(net)).ids and len(env.possible_agents) >= 1
        obs, _ = env.reset(seed=0)
        steps = 0
        while env.agents:
            env.step({a: (steps // 3) % env.action_space(a).n for a in env.agents})  # each green 30 s
            steps += 1
        assert steps == 40
        m = env.episode_metrics()
        assert m["vehicles"] > 20 and m["throughput"] > 0 and np.isfinite(m["delay"])
    finally:
        env.close()


@pytest.mark.parametrize("options, message", [
    ({"net": "cologne9"}, "unknown map 'cologne9'"),
    ({"net": "cologne1", "begin": 28800}, "begin .* must come before end"),
    ({"net_file": "/nonexistent/x.net.xml", "route_files": ["r.xml"]}, "net_file: no such file"),
    ({"net": "cologne1", "learners": ["nobody"]}, "unknown traffic light"),
    ({"net": "cologne1", "max_distance": 0}, "max_distance"),
    ({"net": "cologne1", "observation": "pixels"}, "unknown observation"),
    ({"net": "cologne1", "max_cycles": 0}, "max_cycles"),
    ({"net": "cologne1", "sumocfg": "x"}, "exactly one network"),
    ({"net": "cologne1", "yellow_seconds": 10}, "yellow_seconds"),
    # NaN and infinities name their option (not a bare ValueError/OverflowError from int())
    ({"net": "cologne1", "begin": float("nan")}, "begin must be whole seconds"),
    ({"net": "cologne1", "end": float("inf")}, "end must be whole seconds"),
    ({"net": "cologne1", "decision_seconds": float("-inf")}, "decision_seconds must be whole seconds"),
    ({"net": "cologne1", "yellow_seconds": float("nan")}, "yellow_seconds must be whole seconds"),
    ({"net": "cologne1", "end": "1e400"}, "end must be whole seconds"),
])
def test_bad_input_is_refused_before_sumo_starts(options, message, monkeypatch):
    from ials_zoo.sumo import lease

    monkeypatch.setattr(lease.SimHandle, "__init__", lambda *a, **k: pytest.fail("SUMO was started"))
    with pytest.raises(BadInput, match=message):
        sumo_net_v0.parallel_env(**options)


def test_a_network_without_lights_or_a_missing_route_file_is_refused(tmp_path):
    net = _netgenerate(tmp_path, tls=False)
    routes = tmp_path / "r.rou.xml"
    routes.write_text("<routes/>")
    with pytest.raises(BadInput, match="no traffic light"):
        sumo_net_v0.parallel_env(net_file=str(net), route_files=[str(routes)])
    with pytest.raises(BadInput, match="route_files: no such file"):
        sumo_net_v0.parallel_env(net_file=str(net), route_files=[str(tmp_path / "missing.rou.xml")])
    cfg = tmp_path / "x.sumocfg"
    cfg.write_text('<configuration><input><net-file value="plain.net.xml"/><route-files value="gone.rou.xml"/>'
                   '</input></configuration>')
    with pytest.raises(BadInput, match="route-files: no such file"):
        sumo_net_v0.parallel_env(sumocfg=str(cfg))
    cfg.write_text('<configuration><input><net-file value="plain.net.xml"/><route-files value="r.rou.xml"/>'
                   '<additional-files value="detectors.add.xml"/></input></configuration>')
    with pytest.raises(BadInput, match="sets additional-files, which this env would ignore"):
        sumo_net_v0.parallel_env(sumocfg=str(cfg))
    bad = tmp_path / "bad.net.xml"
    bad.write_text('<net><edge id="e"><lane id="e_0" length="abc" shape="0,0 1,1"/></edge></net>')
    with pytest.raises(BadInput, match="bad.net.xml is not a valid SUMO network"):
        sumo_net_v0.parallel_env(net_file=str(bad), route_files=[str(routes)])
    with pytest.raises(BadInput, match="scripted_learners must be False, True, 'fixed' or 'actuated'"):
        sumo_net_v0.parallel_env(net="cologne1", scripted_learners="maxwave")


def test_a_truncated_route_file_is_refused_before_any_step(tmp_path, monkeypatch):
    """A route file cut off mid-element would run an episode on part of the demand and then fail
    in the metrics: it is refused by name at construction, before SUMO starts."""
    from ials_zoo.sumo import lease

    whole = make_scenario(net="cologne1")
    text = Path(whole.route_files[0]).read_text()
    cut = tmp_path / "cut.rou.xml"
    cut.write_text(text[: len(text) // 2])
    monkeypatch.setattr(lease.SimHandle, "__init__", lambda *a, **k: pytest.fail("SUMO was started"))
    with pytest.raises(BadInput, match="cut.rou.xml is not a whole XML file"):
        sumo_net_v0.parallel_env(net_file=whole.net_file, route_files=[str(cut)])


def test_resco_maps_have_rescos_lights_and_actions():
    """RESCO's counts (its map_config and nets; ingolstadt21 there: 2 x 1, 3 x 15, 4 x 5 greens):
    sumo-rl's ingolstadt21 lacks one green of one junction, so one 4 becomes a 3."""
    counts = {m: [x.n_actions for x in read_network(make_scenario(net=m).net_file).lights]
              for m in ("grid4x4", "arterial4x4", "cologne8", "ingolstadt21")}
    assert counts["grid4x4"] == [8] * 16 and counts["arterial4x4"] == [5] * 16
    assert sorted(counts["cologne8"]) == [2, 2, 3, 3, 3, 4, 4, 4]
    assert sorted(counts["ingolstadt21"]) == [2] + [3] * 16 + [4] * 4
    assert make_scenario(net="arterial4x4").decision_seconds == 5 and make_scenario(net="cologne3").begin == 25200


def test_the_controller_study_stores_episodes_resumes_and_reports_beside_resco(tmp_path, capsys):
    from ials_zoo.cli import main

    argv = ["resco-controllers", "--maps", "cologne1", "--controllers", "fixed,plain_sumo", "--episodes", "1",
            "--seed-base", "7", "--out", str(tmp_path)]
    assert main(argv) == 0
    first = capsys.readouterr().out
    stored = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*.json"))
    assert stored == ["cologne1/fixed/seed_7.json", "cologne1/plain_sumo/seed_7.json"]
    rows = [line for line in first.splitlines() if line.startswith("| cologne1")]
    assert len(rows) == 2 and rows[0].split("|")[4] == rows[1].split("|")[4]  # the env's delay is plain SUMO's
    assert "FIXED: 56.61 / 56.85" in rows[0]
    assert main(argv) == 0 and "2 already stored" in capsys.readouterr().out  # resumed: nothing re-run


def test_long_commands_estimate_a_networks_cost_from_its_map(monkeypatch):
    """A GS episode's estimate follows its map, not its agent count: ingolstadt21 (21 lights)
    costs over 5x cologne8 (8 lights) per episode; a network given by file is charged by its
    lanes, an upper estimate; and fidelity estimates the network it was given."""
    from ials_zoo.cli import main
    from ials_zoo.commands import fidelity as command
    from ials_zoo.errors import BadInput
    from ials_zoo.evaluation import estimate_evaluation_seconds as estimate

    c8, i21 = estimate("sumo_net_v0", 1, net="cologne8"), estimate("sumo_net_v0", 1, net="ingolstadt21")
    assert i21 > 5 * c8
    s = make_scenario(net="cologne8")
    by_file = estimate("sumo_net_v0", 1, net_file=s.net_file, route_files=s.route_files, begin=s.begin, end=s.end)
    assert c8 <= by_file <= 3 * c8
    assert estimate("sumo_net_v0", 1, net="cologne8", max_cycles=36) == pytest.approx(c8 / 10)
    assert estimate("sumo_net_v0", 1, net="cologne8", end=s.begin + 360) == pytest.approx(c8 / 10)  # its first 6 min
    seen = []

    def spy(env_id, episodes, **options):
        seen.append(options)
        raise BadInput("stop here")

    monkeypatch.setattr(command, "estimate_evaluation_seconds", spy)
    assert main(["fidelity", "--env", "sumo_net_v0", "--net", "ingolstadt21", "--episodes", "2"]) == 2
    assert seen == [{"net": "ingolstadt21"}]
