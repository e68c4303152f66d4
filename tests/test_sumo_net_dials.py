"""DIALS on a real network (``sumo_net_v0``, whose lights have spaces of their own): every
light's PPO on copies of the multi-agent IALS ParallelEnv, the AIPs retrained on GS data from
the joint policy (:mod:`ials_zoo.baselines.dials_copies`). cologne3: three lights of three
shapes, 30-decision episodes."""

import json

import numpy as np
import pytest
from same_run import assert_same_run
from test_exact_resume import _progress_rows, _stopped_and_resumed

from ials_zoo.errors import BadInput

OPTIONS = {"net": "cologne3", "max_cycles": 30}
# AIP rounds at 0 and 128 steps per light, checkpoints every 64: the crash at the third
# evaluation (192) resumes from 128, before that round, in the middle of an IALS episode
DIALS = dict(env_id="sumo_net_v0", env_options=json.dumps(OPTIONS), n_envs=2, samples_per_update=64, batch_size=32,
             n_epochs=2, hidden="16", eval_episodes=1, final_eval_episodes=1, progress=False, total_timesteps=256,
             eval_every=64, refresh="128", collect_steps=60, aip_epochs=2, workers=2)


@pytest.fixture(scope="module")
def whole_run(tmp_path_factory):
    """The reference run: IALS copies in 2 worker processes, never stopped."""
    from ials_zoo.baselines import dials

    out = tmp_path_factory.mktemp("dials_copies") / "whole"
    return dials.main(dials.Args(**DIALS, out_dir=str(out))), out


def test_dials_trains_lights_of_their_own_shapes_on_ials_copies_and_resumes_bitwise(tmp_path, monkeypatch, whole_run):
    from ials_zoo.baselines import dials
    from ials_zoo.influence.files import load_predictor_set

    whole = whole_run
    result = whole[0]
    assert result["training"]["simulator"] == "dials" and result["training"]["aip"]["refreshes"] == 2
    aips = load_predictor_set(whole[1] / "aips.pt", env_id="sumo_net_v0")
    assert len({(p.region.n_sources, p.region.dset_size("dset")) for p in aips.values()}) == 3  # three shapes
    assert all(p.metadata["variant"] == "trained" for p in aips.values())
    resumed = _stopped_and_resumed(monkeypatch, dials, tmp_path / "resumed", DIALS)
    assert_same_run(whole, resumed)
    assert _progress_rows(whole[1]) == _progress_rows(resumed[1])


def test_dials_on_a_two_node_ray_cluster_is_the_same_run(tmp_path, whole_run):
    """The IALS copies as Ray actors, one on each node of a two-node cluster
    (``ray.cluster_utils.Cluster``, both on this machine): the same weights, curve and scores as
    in worker processes."""
    ray = pytest.importorskip("ray")
    from ray.cluster_utils import Cluster

    from ials_zoo.baselines import dials

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    try:
        cluster.add_node(num_cpus=1)
        cluster.wait_for_nodes()
        args = dials.Args(**DIALS, backend="ray", ray_address=cluster.address, out_dir=str(tmp_path / "ray"))
        on_ray = dials.main(args), tmp_path / "ray"
        assert on_ray[0]["training"]["backend"] == "ray"
        assert_same_run(whole_run, on_ray)
    finally:
        if ray.is_initialized():
            ray.shutdown()
        cluster.shutdown()


def _one_network(layers) -> bool:
    """Whether every agent's actor is one network's: the same weights everywhere, the first
    layer's bias apart (where shared PPO folds an agent's id)."""
    same = [np.array_equal(t, t[:1].repeat(len(t), 0)) for t in (t for W, b in layers for t in (W, b))]
    return all(same[:1] + same[2:]) and not same[1]


def test_dials_with_the_shared_learner_trains_one_network_for_every_light(tmp_path, whole_run):
    """``--learner shared``: shared PPO's one actor-critic (:class:`~ials_zoo.learners.batched_ppo.SharedPPO`)
    on the IALS copies; IPPO's learner (the reference run) keeps a network per light."""
    from ials_zoo.baselines import dials
    from ials_zoo.policy import load_policy_file

    run = {**DIALS, "aip": "untrained", "refresh": "never", "total_timesteps": 128, "eval_every": 128}
    result = dials.main(dials.Args(**run, learner="shared", out_dir=str(tmp_path / "shared")))
    assert result["training"]["simulator"] == "untrained-dials-shared"
    assert result["training"]["hyperparameters"]["learner"] == "shared"
    assert _one_network(load_policy_file(tmp_path / "shared" / "policy.safetensors").layers)
    assert not _one_network(load_policy_file(whole_run[1] / "policy.safetensors").layers)


@pytest.mark.parametrize("flag,value", [("learner", "sb3"), ("aip", "shipped"), ("workers", 0)])
def test_what_the_ials_copies_cannot_do_is_named_before_any_work(tmp_path, flag, value):
    from ials_zoo.baselines import dials

    with pytest.raises(BadInput, match=f"--{flag}"):
        dials.main(dials.Args(**{**DIALS, flag: value, "backend": "ray"}, out_dir=str(tmp_path / "run")))
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("option", [{"observation": "wave"}, {"observation": "mplight"}, {"reward": "pressure"}])
def test_an_observation_or_reward_of_the_gs_only_is_refused_before_any_work(tmp_path, option):
    from ials_zoo.baselines import dials

    options = json.dumps({**json.loads(DIALS["env_options"]), **option})
    with pytest.raises(BadInput, match=f"--env-options: .*{next(iter(option))}={next(iter(option.values()))!r}"):
        dials.main(dials.Args(**{**DIALS, "env_options": options}, out_dir=str(tmp_path / "run")))
    assert not (tmp_path / "run").exists()


def test_new_aips_drive_the_ials_copies_from_the_next_decision():
    """``make_ials_vector_env``'s ``set_predictors`` reaches every copy in its worker: a uniform AIP (a third each of 0, 1
    and 2+ vehicles per second and entry point) after the recorded frequencies (a few percent)."""
    import ials_zoo
    from ials_zoo.sumo_net.island import gs_marginal_predictors

    light = "GS_cluster_357187_359543"
    options = {"net": "cologne1", "max_cycles": 20}
    recorded = gs_marginal_predictors([light], **options)
    rewards = {}
    for name, later in (("recorded", None), ("uniform", {light: "uniform"})):
        env = ials_zoo.make_ials_vector_env("sumo_net_v0", recorded, [light], n_envs=2, processes=2, **options)
        try:
            env.reset(seed=0)
            got = []
            for k in range(12):
                if k == 4 and later is not None:
                    env.set_predictors(later)
                got.append(env.step(np.full((1, 2), k % 2, np.int64))[1].mean())  # the two greens in turn
        finally:
            env.close()
        rewards[name] = float(np.mean(got[8:]))
    # the flooded region waits far longer (measured -1.51 and -3.95): the reward (minus the wait) falls
    assert rewards["uniform"] < 2 * rewards["recorded"] < 0, rewards


def test_fidelity_passes_on_policy_aips_and_fails_a_flooding_one_on_a_real_network(tmp_path):
    """``ials-zoo fidelity`` on lights of their own shapes, on either local simulator (SUMO
    regions, arrays): with AIPs trained on the GS's data of the same (random) joint policy the
    share of seconds a vehicle enters is within a factor 1.5 of the GS's; a uniform AIP (a vehicle
    at two seconds of three, 10-30 times the GS's share) fails the report's test. Three episodes
    are few for the report's own verdict on the on-policy AIPs, which held them at some seeds only:
    the IALS drew 0.81-0.83 (busier light) and 1.09-1.47 (quieter) of the GS's share on SUMO
    regions at seeds 0-1, 0.77-0.87 and 0.84-1.18 on arrays at seeds 0-2. Six GS episodes of data need 600 epochs: at 150 (150 updates) the quieter light's AIP
    ran 50% high."""
    from ials_zoo.influence.fidelity import fidelity_report
    from ials_zoo.influence.files import save_predictor_set
    from ials_zoo.influence.multi import resolve_predictor_set

    options = {"net": "cologne3", "max_cycles": 20}
    common = dict(episodes=3, seed=0, watched=["360082", "360086"], progress=False, **options)
    agents = ["360082", "360086", "GS_cluster_2415878664_254486231_359566_359576"]
    uniform = tmp_path / "uniform.pt"
    save_predictor_set(resolve_predictor_set("uniform", "sumo_net_v0", agents, options=options), uniform)
    returns = {}
    for local in ("sumo", "arrays"):
        good = fidelity_report("sumo_net_v0", ["random"], predictor="on-policy", collect_steps=120, aip_epochs=600,
                               ials_options={"local": local}, **common)
        bad = fidelity_report("sumo_net_v0", ["random"], predictor=str(uniform), ials_options={"local": local},
                              **common)
        for light in common["watched"]:
            rows, flooded = good["policies"]["random"][light], bad["policies"]["random"][light]
            assert 2 / 3 < rows["active"]["ials"] / rows["active"]["gs"] < 1.5, (local, rows["active"])
            assert rows["active"]["gs"] == flooded["active"]["gs"]  # the same GS episodes
            assert not flooded["active"]["holds"] and flooded["active"]["ials"] > 0.5, (local, flooded["active"])
        returns[local] = [good["policies"]["random"][x]["return"]["ials"] for x in common["watched"]]
    assert returns["sumo"] != returns["arrays"]  # two simulators ran, not one twice
