"""The domain contract, checked on every registered domain: the two real ones and ``relay_v0``,
a toy domain that lives only in ``tests/toy_relay`` and is registered at run time."""

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test, parallel_seed_test, render_test
from pettingzoo.utils import parallel_to_aec

import ials_zoo
from ials_zoo.core.domains import Domain, domain_ids, get_domain, register_domain, unregister_domain
from ials_zoo.core.region import DSET_KINDS, INFLUENCE_KEY

TOY = "relay_v0"


@pytest.fixture(scope="module", autouse=True)
def toy_domain():
    from toy_relay.domain import DOMAIN

    register_domain(DOMAIN, replace=True)
    yield DOMAIN
    unregister_domain(TOY)


def domains():
    import toy_relay.domain  # noqa: F401 - the ids are listed before the fixture registers it

    return ["traffic_grid_v0", "warehouse_v0", TOY]


# agents with their own spaces: the GS half of the contract, one junction's IALS
# (tests/test_sumo_net_ials.py) and DIALS on copies of its multi-agent IALS ParallelEnv
# (tests/test_sumo_net_dials.py), but not the tools that stack agents of one shape
OWN_SPACES = ["sumo_net_v0"]


@pytest.fixture(params=domains())
def domain(request) -> Domain:
    """A domain with an IALS: the whole contract."""
    return get_domain(request.param)


@pytest.fixture(params=domains() + OWN_SPACES)
def any_domain(request) -> Domain:
    """Every domain: the GS half of the contract."""
    return get_domain(request.param)


def test_domains_with_their_own_spaces_say_so_and_the_multi_agent_tools_refuse_them_by_name():
    from ials_zoo.baselines.dials import on_copies
    from ials_zoo.core.domains import ials_domain_ids
    from ials_zoo.errors import BadInput

    assert set(OWN_SPACES) <= set(domain_ids()) and not set(OWN_SPACES) & set(ials_domain_ids())
    assert set(domains()) - {TOY} <= set(ials_domain_ids())
    for env_id in OWN_SPACES:
        d = get_domain(env_id)
        assert not d.has_ials and d.has_local_simulator and d.observation_space is None
        assert d.require_local_simulator("make_ials") is d
        with pytest.raises(BadInput, match=f"train ippo needs a local simulator and shared agent spaces.*{env_id}"):
            d.require_ials("train ippo")
        with pytest.raises(BadInput, match="own action space"):
            d.n_actions  # noqa: B018
        with pytest.raises(BadInput, match="make_multi_agent_ials needs a local simulator and shared agent spaces"):
            ials_zoo.make_multi_agent_ials(env_id)
        assert d.ials_parallel_env is not None  # its own multi-agent IALS (tests/test_sumo_net_ials.py)
        assert on_copies(d)  # which DIALS trains on
    gs_only = Domain(env_id="gs_only_v0", parallel_env=dict, possible_agents=list, default_agents=("a",),
                     episode_length=1)
    assert not gs_only.has_local_simulator
    with pytest.raises(BadInput, match="make_ials needs a local simulator, which gs_only_v0"):
        gs_only.require_local_simulator("make_ials")
    with pytest.raises(BadInput, match="needs region_spec"):
        Domain(env_id="half_v0", parallel_env=dict, possible_agents=list, default_agents=("a",), episode_length=1,
               local_simulator=dict)


def test_registration(toy_domain):
    assert TOY in domain_ids() and get_domain(TOY) is toy_domain
    with pytest.raises(ValueError, match="already registered"):
        register_domain(toy_domain)
    with pytest.raises(ValueError, match="unknown domain 'nope_v0'"):
        get_domain("nope_v0")
    # its IALS is a Gymnasium env at once
    import gymnasium

    env = gymnasium.make(f"ials_zoo/IALS-{TOY}", agent="node_2", predictor="uniform")
    env.reset(seed=0)
    env.close()


def test_bare_gymnasium_make_with_the_module_prefix():
    """Gymnasium 1.x has no plugin entry points: the module prefix imports the zoo."""
    import subprocess
    import sys

    code = ("import gymnasium; e = gymnasium.make('ials_zoo:ials_zoo/IALS-warehouse_v0', agent='robot_20', "
            "predictor='uniform'); print(e.reset(seed=0)[0].shape)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "(37,)"


def _gs(domain, **kw):
    return domain.parallel_env(**kw)


def test_pettingzoo_api_and_seeding(any_domain):
    domain = any_domain
    agent = domain.default_agents[0]
    for learners in (None, [agent]):
        env = _gs(domain, learners=learners)
        parallel_api_test(env, num_cycles=domain.episode_length + 5)
        env.close()
    parallel_seed_test(lambda: _gs(domain, learners=[agent]))


def test_aec_raw_env_and_render_modes(any_domain):
    domain = any_domain
    env = _gs(domain, learners=[domain.default_agents[0]])
    modes = env.metadata["render_modes"]
    env.close()
    assert "human" in modes

    def make(render_mode=None):
        return parallel_to_aec(_gs(domain, learners=[domain.default_agents[0]], render_mode=render_mode))

    render_test(make)


def test_infos_have_the_same_keys_shapes_and_dtypes_at_reset_and_step(domain):
    agent = domain.default_agents[0]
    env = _gs(domain, learners=[agent])
    region = domain.region_spec(agent)
    _, infos = env.reset(seed=0)
    _, _, _, _, infos2 = env.step({agent: 0})
    env.close()
    for info in (infos[agent], infos2[agent]):
        assert set(info) == {INFLUENCE_KEY, "dset", "dset_full"}
        assert info[INFLUENCE_KEY].shape == (region.n_sources,) and info[INFLUENCE_KEY].dtype == np.int64
        assert info["dset"].shape == (region.dset_size("dset"),) and info["dset"].dtype == np.uint8
        assert info["dset_full"].shape == (region.dset_size("full"),)
    assert {k: (v.shape, v.dtype) for k, v in infos[agent].items()} == {
        k: (v.shape, v.dtype) for k, v in infos2[agent].items()}


def test_state_matches_state_space(any_domain):
    domain = any_domain
    env = _gs(domain, learners=[domain.default_agents[0]])
    env.reset(seed=1)
    s = env.state()
    assert env.state_space.contains(s) and s.dtype == np.float32
    env.close()


def test_region_spec_agrees_between_gs_ls_and_domain(domain):
    for agent in (domain.default_agents[0], domain.agents()[0]):
        env = _gs(domain, learners=[agent])
        ls = domain.local_simulator(agent, n_envs=2)
        try:
            assert env.region_spec(agent) == domain.region_spec(agent) == ls.region
            assert ls.observation_space == domain.observation_space == env.observation_space(agent)
            assert ls.action_space == domain.action_space == env.action_space(agent)
            obs, dsets = ls.reset(seed=0)
            assert obs.shape == (2, *domain.observation_space.shape)
            for kind in DSET_KINDS:
                assert dsets[kind].shape == (2, ls.region.dset_size(kind))
        finally:
            env.close()
            ls.close()
    with pytest.raises(ValueError, match="unknown agent"):
        domain.check_agent("nobody_99")


def test_ls_replays_the_gs_given_its_influence_sources(domain):
    """Fed the GS's own actions and influence sources, the LS tracks the GS's observations (a
    domain declares how closely: exactly where its LS has no other randomness)."""
    agent = domain.default_agents[0]
    env = _gs(domain, learners=[agent])
    ls = domain.local_simulator(agent, n_envs=1)
    rng = np.random.default_rng(0)
    agree, active = [], 0
    try:
        obs, _ = env.reset(seed=3)
        ls_obs, _ = ls.reset(seed=3)
        while env.agents:
            a = int(rng.integers(domain.n_actions))
            obs, _, _, _, infos = env.step({agent: a})
            u = infos[agent][INFLUENCE_KEY]
            active += int((u != domain.null_influence).sum())
            ls_obs, _, _ = ls.step(np.array([a]), u[None])
            agree.append(np.mean(ls_obs[0] == obs[agent]))
    finally:
        env.close()
        ls.close()
    assert active > 0  # the replay did exercise the influence sources
    assert np.mean(agree) >= domain.replay_agreement, np.mean(agree)


def test_the_ials_steps_and_passes_gymnasiums_checker(domain):
    env = ials_zoo.make_ials(domain.env_id, domain.default_agents[0], predictor="uniform", seed=0)
    try:
        check_env(env, skip_render_check=True)
        obs, _ = env.reset(seed=1)
        total, steps, done = 0.0, 0, False
        while not done:
            obs, r, term, trunc, info = env.step(env.action_space.sample())
            total += r
            steps += 1
            done = term or trunc
        assert steps == domain.episode_length and np.isfinite(total)
        assert info[INFLUENCE_KEY].shape == (domain.region_spec(domain.default_agents[0]).n_sources,)
    finally:
        env.close()


def test_nothing_outside_a_domain_folder_names_a_domain():
    """Generic code asks the Domain; domain ids appear only in their folders (and in the
    paper's reference numbers, which document paper data)."""
    import re
    from pathlib import Path

    root = Path(ials_zoo.__file__).parent
    ids = [d for d in domain_ids() if d != TOY]
    allowed = {"reproduce/claims.py"}  # PAPER: the paper's reference numbers per domain
    offenders = []
    for path in root.rglob("*.py"):
        rel = path.relative_to(root).as_posix()
        if (root / rel.split("/")[0] / "domain.py").is_file() or rel.endswith(("_v0.py",)) or rel in allowed:
            continue
        code = re.sub(r'("""|\'\'\')(.|\n)*?\1', "", path.read_text())  # docstrings document, code decides
        code = "\n".join(line.split("#", 1)[0] for line in code.splitlines())
        for env_id in ids:
            if re.search(rf"[\"']{env_id}[\"']", code):
                offenders.append(f"{rel}: {env_id}")
    assert not offenders, offenders


def _two_agents(domain):
    agents = domain.agents()
    return [domain.default_agents[0], next(a for a in agents if a != domain.default_agents[0])]


def test_a_copy_behaves_the_same_in_any_batch(domain):
    """Fed the same actions and influences, an agent's copies in a local simulator of several
    agents follow those of a local simulator of that agent alone (per-copy random streams):
    what DIALS computes does not depend on how its agents are split over workers."""
    # an agent in the middle of a batch of every agent (its copy far from copy 0), for three
    # episodes of busy influence: a copy's dynamics must not depend on its index (in
    # traffic, copies at other network coordinates once got other lane geometry)
    agents = domain.agents()
    k = min(7, len(agents) - 1)
    mine = agents[k]
    n = len(agents)
    both = domain.local_simulator(agents, n_envs=1)
    alone = domain.local_simulator([mine], n_envs=1)
    rng = np.random.default_rng(0)
    region = domain.region_spec(mine)
    try:
        for step in range(3 * domain.episode_length):
            if step % domain.episode_length == 0:
                seed = 5 + step // domain.episode_length
                o_both, d_both = both.reset(seed=seed)
                o_alone, d_alone = alone.reset(seed=seed)
                np.testing.assert_array_equal(o_both[k:k + 1], o_alone)
            acts = rng.integers(domain.n_actions, size=n)
            u = np.stack([rng.integers(c, size=n) for c in region.influence_classes], axis=1)
            u[rng.random(u.shape) < 0.4] = domain.null_influence  # busy, not jammed
            o_both, r_both, d_both = both.step(acts, u)
            o_alone, r_alone, d_alone = alone.step(acts[k:k + 1], u[k:k + 1])
            np.testing.assert_array_equal(o_both[k:k + 1], o_alone)
            np.testing.assert_array_equal(np.asarray(r_both)[k:k + 1], r_alone)
            np.testing.assert_array_equal(d_both["dset"][k:k + 1], d_alone["dset"])
    finally:
        both.close()
        alone.close()


def test_the_multi_agent_ials_is_a_pettingzoo_parallel_env(domain):
    pair = _two_agents(domain)

    def make():
        return ials_zoo.make_ials_parallel_env(domain.env_id, pair, predictor="untrained", seed=0)

    env = make()
    parallel_api_test(env, num_cycles=domain.episode_length + 5)
    env.close()
    parallel_seed_test(make)
    env = make()
    obs, infos = env.reset(seed=2)
    assert sorted(obs) == sorted(pair) and env.state_space.contains(env.state())
    assert {k: v.shape for k, v in infos[pair[0]].items()} == {
        INFLUENCE_KEY: (domain.region_spec(pair[0]).n_sources,), "dset": (domain.region_spec(pair[0]).dset_size("dset"),),
        "dset_full": (domain.region_spec(pair[0]).dset_size("full"),)}
    env.close()


def test_subsystem_settings_live_in_extras_with_defaults_and_typos_are_refused():
    """A domain gives the core contract; each subsystem's settings are optional extras (the
    toy gives only "study"), read through ials_zoo.core.extras with defaults."""
    import dataclasses

    from ials_zoo.core.domains import Domain
    from ials_zoo.core.extras import (
        BenchSettings,
        DIALSSettings,
        ViewerSettings,
        bench_of,
        dials_of,
        tools_of,
        viewer_of,
    )
    from ials_zoo.errors import BadInput

    toy = get_domain(TOY)
    assert dials_of(toy) == DIALSSettings() and viewer_of(TOY) == ViewerSettings()
    assert bench_of(toy) == BenchSettings() and tools_of(toy) == {}
    with pytest.raises(BadInput, match="unknown extras \\['studdy'\\]"):
        dataclasses.replace(toy, extras={"studdy": None})
    assert not {"study", "dials", "legend", "tools", "scaling", "episode_summary"} & {f.name for f in dataclasses.fields(Domain)}


def test_a_domain_registered_at_run_time_reaches_worker_processes():
    """A worker (processes.Worker: a fresh interpreter) gets the run-time registered domains
    and sys.path: IPPO's GS copies of the toy domain step in a worker as in this process."""
    from ials_zoo.learners.gs_vec import GSVecEnv

    agents = get_domain(TOY).agents()
    here, there = GSVecEnv(TOY, agents, n_envs=1, processes=0, seed=3), GSVecEnv(TOY, agents, n_envs=1, processes=1, seed=3)
    try:
        np.testing.assert_array_equal(here.reset(seed=5), there.reset(seed=5))
        actions = np.zeros((len(agents), 1), dtype=np.int64)
        for _ in range(5):
            a, b = here.step(actions), there.step(actions)
            np.testing.assert_array_equal(a[0], b[0])
            np.testing.assert_array_equal(a[1], b[1])
    finally:
        here.close()
        there.close()
