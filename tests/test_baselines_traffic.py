"""Baselines and evaluation on the SUMO traffic grid (real SUMO, kept short)."""

import json

import pytest

from ials_zoo.baselines import ppo_single
from ials_zoo.evaluation import evaluate
from ials_zoo.leaderboard import load_result

ENV, AGENT = "traffic_grid_v0", "tls_12"
TINY = dict(env_id=ENV, agent=AGENT, total_timesteps=600, n_envs=2, n_steps=150, batch_size=150,
            net_arch="16", eval_every=300, eval_episodes=1, final_eval_episodes=2, progress=False)


def test_traffic_evaluation_is_deterministic():
    a = evaluate(ENV, AGENT, "scripted", episodes=1)
    b = evaluate(ENV, AGENT, "scripted", episodes=1)
    assert a.returns == b.returns and a.episode_length == 300


def _check(out, simulator, result):
    data = load_result(out / "result.json")
    assert data == result and data["training"]["simulator"] == simulator
    curve = json.loads((out / "curve.json").read_text())["points"]
    assert [p["env_steps"] for p in curve] == [0, 300, 600]
    assert curve[2]["wall_clock_seconds"] > curve[1]["wall_clock_seconds"]
    # scored again later from the saved file, in this process (training ran its GS copies and
    # evaluations in worker processes, so no libsumo simulation is live here)
    again = evaluate(ENV, AGENT, str(out / "policy.safetensors"), episodes=2)
    assert again.returns == data["scores"][0]["returns"]
    return data


def test_ppo_single_traffic_gs(tmp_path):
    out = tmp_path / "gs"
    _check(out, "gs", ppo_single.main(ppo_single.Args(simulator="gs", out_dir=str(out), **TINY)))


@pytest.fixture(scope="module")
def traffic_aip(tmp_path_factory):
    from ials_zoo.influence.dataset import collect
    from ials_zoo.influence.files import save_predictor
    from ials_zoo.influence.train import train_predictor

    data = collect(ENV, AGENT, steps=600, progress=False)
    pred, _ = train_predictor(data, arch="mlp", epochs=1, progress=False)
    return str(save_predictor(pred, tmp_path_factory.mktemp("aip") / "tls12.pt"))


def test_ppo_single_traffic_ials(tmp_path, traffic_aip):
    out = tmp_path / "ials"
    data = _check(out, "ials", ppo_single.main(
        ppo_single.Args(simulator=traffic_aip, out_dir=str(out), **TINY)))
    assert data["training"]["aip"]["collection_seconds"] > 0
    assert data["training"]["aip"]["file"] == traffic_aip
    assert data["training"]["aip_seconds"] > 0


def test_ppo_shared_traffic_copies_in_own_processes(tmp_path):
    from ials_zoo.baselines import ppo_shared

    out = tmp_path / "shared"
    results = ppo_shared.main(ppo_shared.Args(
        env_id=ENV, learners="tls_12,tls_13", total_timesteps=600, n_copies=2, n_steps=150,
        batch_size=150, net_arch="16", eval_every=0, eval_episodes=1, final_eval_episodes=1,
        out_dir=str(out), progress=False))
    assert [r["agent"] for r in results] == ["tls_12"]  # default: default agents among learners
    assert load_result(out / "result_tls_12.json")["trained_agents"] == ["tls_12", "tls_13"]
    with pytest.raises(ValueError, match="must be learners"):
        ppo_shared.main(ppo_shared.Args(env_id=ENV, learners="tls_12", eval_agents="tls_18",
                                        out_dir=str(out), progress=False))
