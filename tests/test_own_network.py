"""A network of the user's own (``sumocfg=`` / ``net_file=``): the baselines train and evaluate
on it, its paths made absolute so that the run works from any folder; only the board keeps to
its own maps."""

from __future__ import annotations

import json
import os
import subprocess

import pytest

from ials_zoo.sumo.command import sumo_binary

TINY = ["--total-timesteps", "256", "--samples-per-update", "128", "--batch-size", "64", "--hidden", "16",
        "--eval-episodes", "1", "--final-eval-episodes", "2", "--no-progress"]


@pytest.fixture(scope="module")
def own_network(tmp_path_factory):
    """A 3x3 grid of lights made with SUMO's netgenerate, 80 trips, 400 s: ``my.sumocfg``."""
    folder = tmp_path_factory.mktemp("own")
    netgenerate = os.path.join(os.path.dirname(sumo_binary()), "netgenerate")
    subprocess.run([netgenerate, "--grid", "--grid.number", "3", "--grid.length", "100", "--no-turnarounds", "true",
                    "--default-junction-type", "traffic_light", "--seed", "1", "-o", str(folder / "g.net.xml")],
                   check=True, capture_output=True, timeout=120)
    trips = "".join(f'<trip id="t{i}" depart="{i * 3}" from="A0B0" to="B2C2"/>' for i in range(80))
    (folder / "r.rou.xml").write_text(f"<routes>{trips}</routes>")
    (folder / "my.sumocfg").write_text('<configuration><input><net-file value="g.net.xml"/><route-files '
                                       'value="r.rou.xml"/></input><time><begin value="0"/><end value="400"/>'
                                       "</time></configuration>")
    return folder


@pytest.mark.parametrize("baseline, extra", [
    ("ippo", []), ("dials", ["--refresh", "once", "--collect-steps", "100", "--aip-epochs", "2"])])
def test_a_baseline_trains_on_a_users_own_network_and_the_board_refuses_it(own_network, tmp_path, monkeypatch,
                                                                            capsys, baseline, extra):
    from ials_zoo.cli import main

    monkeypatch.chdir(own_network)  # the user's folder: the paths they give are relative to it
    out = tmp_path / "run"
    assert main(["train", baseline, "--env", "sumo_net_v0", "--env-options", '{"sumocfg": "my.sumocfg"}',
                 *TINY, *extra, "--out-dir", str(out)]) == 0
    result = json.loads((out / "result.json").read_text())
    options = result["evaluation"]["options"]
    assert options == {"sumocfg": str(own_network / "my.sumocfg")} and result["evaluation"]["protocol"] == "variant"
    assert len(result["agents"]) == 5 and "delay" in result["metrics"]
    assert str(own_network / "my.sumocfg") in result["training"]["reproduce"]["command"]
    monkeypatch.chdir(tmp_path)  # from another folder, the policy and its options still work
    capsys.readouterr()
    assert main(["evaluate", "--env", "sumo_net_v0", "--joint", "--policy", str(out / "policy.safetensors"),
                 "--env-options", json.dumps(options), "--episodes", "1"]) == 0
    board = tmp_path / "board"
    (board / "results").mkdir(parents=True)
    assert main(["leaderboard", "submit", str(out / "result.json"), "--dir", str(board)]) == 1
    assert "name files of a network of your own" in capsys.readouterr().err
    assert not any((board / "results").iterdir())


def test_net_file_and_route_files_become_absolute_and_other_options_are_refused_by_name(own_network, monkeypatch):
    from ials_zoo.baselines import ippo
    from ials_zoo.errors import BadInput

    monkeypatch.chdir(own_network)
    args = ippo.Args(env_id="sumo_net_v0", env_options='{"net_file": "g.net.xml", "route_files": ["r.rou.xml"]}')
    _, agents, options, _ = ippo.check_args(args)
    assert options == {"net_file": str(own_network / "g.net.xml"), "route_files": [str(own_network / "r.rou.xml")]}
    assert json.loads(args.env_options) == options and len(agents) == 5  # recorded whole
    with pytest.raises(BadInput, match=r"\['region_data'\] are not options of sumo_net_v0's GS"):
        ippo.check_args(ippo.Args(env_id="sumo_net_v0", env_options='{"net": "cologne1", "region_data": true}'))


def test_a_flag_named_result_error_from_a_baseline_is_one_line(monkeypatch, capsys):
    """A baseline's ResultError (a field and a message) named by its flag: one line, exit 2, not
    a second traceback from rebuilding the exception."""
    from ials_zoo.baselines import ippo
    from ials_zoo.cli import main
    from ials_zoo.leaderboard.validate import ResultError

    def fail(args):
        raise ResultError("total_timesteps", "too many")

    monkeypatch.setattr(ippo, "main", fail)
    assert main(["train", "ippo", "--env", "warehouse_v0"]) == 2
    err = capsys.readouterr().err
    assert "--total-timesteps: too many" in err and "Traceback" not in err
