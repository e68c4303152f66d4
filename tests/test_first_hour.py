"""The first hour as a newcomer meets it: refusals before any work, help that says what a
command takes, a network of one's own on every command that draws or trains."""

from __future__ import annotations

import pytest
from test_own_network import own_network  # noqa: F401  (a 3x3 netgenerate grid of lights, my.sumocfg)
from test_trust3 import _board, scripted  # noqa: F401

from ials_zoo.cli import main


def test_version(capsys):
    import ials_zoo

    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0 and capsys.readouterr().out.strip() == f"ials-zoo {ials_zoo.__version__}"


def test_fidelity_without_aips_is_refused_before_any_episode(tmp_path, monkeypatch, capsys):
    from ials_zoo.influence import fidelity

    monkeypatch.setenv("IALS_ZOO_CACHE", str(tmp_path))  # no AIP cached here
    monkeypatch.setattr(fidelity, "_gs_summary", lambda *a, **k: pytest.fail("a GS episode ran"))
    assert main(["fidelity", "--env", "sumo_net_v0", "--net", "cologne1", "--episodes", "2"]) == 2
    err = capsys.readouterr().err
    assert "no trained influence predictor" in err and "`--predictor train` on the command line" in err


def test_bench_refuses_an_unknown_map_before_measuring_anything(monkeypatch, capsys):
    from ials_zoo.commands import bench

    monkeypatch.setattr(bench, "machine_info", lambda: pytest.fail("it measured"))
    assert main(["bench", "--domain", "sumo_net_v0", "--net", "colgne8"]) == 2
    assert "--net: unknown map(s) ['colgne8']" in capsys.readouterr().err


def test_a_duplicate_submission_is_refused_before_its_re_measure(tmp_path, scripted, monkeypatch):  # noqa: F811
    from ials_zoo import leaderboard as lb
    from ials_zoo.leaderboard import store

    board = _board(tmp_path)
    path = tmp_path / "r.json"
    lb.write_result(path, scripted)
    lb.submit(path, board, remeasure=False)
    monkeypatch.setattr(store, "remeasure_result", lambda *a, **k: pytest.fail("it re-measured"))
    with pytest.raises(lb.ResultError, match="duplicate"):
        lb.submit(path, board)


def test_demo_draws_a_network_of_ones_own(own_network, capsys):  # noqa: F811
    assert main(["demo", "--domain", "sumo_net_v0", "--sumocfg", str(own_network / "my.sumocfg"), "--steps", "3"]) == 0
    assert "sumo_net_v0: 3 steps" in capsys.readouterr().out
    assert main(["demo", "--domain", "warehouse_v0", "--sumocfg", "x.sumocfg"]) == 2
    assert "takes no network of your own" in capsys.readouterr().err


def test_a_light_of_one_green_is_no_agent(own_network):  # noqa: F811
    from ials_zoo.sumo_net.network import read_network

    lights = read_network(str(own_network / "g.net.xml")).lights
    assert len(lights) == 5 and min(x.n_actions for x in lights) >= 2  # the 4 corners have one green


def test_ppo_single_on_a_domain_of_per_agent_spaces_says_what_it_lacks(capsys):
    assert main(["train", "ppo_single", "--env", "sumo_net_v0"]) == 2
    err = capsys.readouterr().err
    assert "its agents each have their own spaces" in err and "does not have yet" not in err


def test_train_requires_the_domain_and_lists_it_first(capsys):
    """The parser itself requires ``--env`` (its usage showed it optional); a baseline called
    from Python without one still names the domains (its own check)."""
    from ials_zoo.baselines import dials
    from ials_zoo.errors import BadInput

    for baseline in ("ippo", "dials", "ppo_single", "ppo_shared"):
        with pytest.raises(SystemExit) as done:
            main(["train", baseline, "--total-timesteps", "5"])
        assert done.value.code == 2 and "required: --env" in capsys.readouterr().err
    with pytest.raises(BadInput, match="--env, one of sumo_net_v0, traffic_grid_v0, warehouse_v0"):
        dials.main(dials.Args())
    with pytest.raises(SystemExit):
        main(["train", "ippo", "--help"])
    usage = capsys.readouterr().out
    assert usage.index("--env ENV_ID") < usage.index("--n-epochs")


def test_evaluate_and_fidelity_name_their_domains(capsys):
    for command in ("evaluate", "fidelity"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        assert "domain id, one of sumo_net_v0, traffic_grid_v0, warehouse_v0" in text


def test_bench_says_what_all_covers_and_gives_a_verdict_across_domains(capsys):
    from ials_zoo.bench.report import verdict

    with pytest.raises(SystemExit):
        main(["bench", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "'all' (the default): every domain whose agents share their spaces" in text and "sumo_net_v0" in text

    def row(name, speed, cost):
        return {"domain": name, "single_agent": {"ials_vs_gs_speed": {"median": speed}},
                "every_agent": {"ials_dials_cost_vs_gs": {"median": cost}}}

    lines = verdict([row("warehouse_v0", 1.2, 0.06), row("traffic_grid_v0", 3.0, 1.3)])
    assert "warehouse_v0 1.2x as fast for one learner, 0.06x the GS's cost" in lines[0]
    assert "pays (costs less than the GS) in: warehouse_v0 on this machine" in lines[1]
