"""One error style for the whole CLI: bad input is refused before any work starts, as
``ials-zoo <command>: <what is wrong>`` on stderr, exit status 2, no traceback."""

from __future__ import annotations

import os
import pickle

import pytest

from ials_zoo.cli import main


@pytest.fixture
def files(tmp_path):
    (tmp_path / "adir").mkdir()
    (tmp_path / "afile").write_text("x")
    (tmp_path / "trunc.npz").write_bytes(b"PK\x03\x04" + b"\0" * 10)
    (tmp_path / "random.npz").write_bytes(os.urandom(200))
    (tmp_path / "pickled.npz").write_bytes(pickle.dumps({"dset": 1}))
    return tmp_path


CASES = [
    (["bench", "--domain", "warehouse_v0", "--versus", "{d}/nowhere.pt"], "no such AIP set file"),
    (["bench", "--domain", "warehouse_v0", "--aip-archs", "gru-64-ar,lstm-8"], "expected ARCH-HIDDEN"),
    (["bench", "--domain", "warehouse_v0", "--aip-archs", "gru-0"], "expected ARCH-HIDDEN"),
    (["fidelity", "--env", "warehouse_v0", "--predictor", "on-policy", "--aip-lr", "0"], "--aip-lr"),
    (["fidelity", "--env", "warehouse_v0", "--predictor", "on-policy", "--aip-seeds", "0"], "--aip-seeds"),
    (["fidelity", "--env", "warehouse_v0", "--predictor", "on-policy", "--aip-lr-schedule", "cosine"],
     "--aip-lr-schedule"),
    (["fidelity", "--env", "warehouse_v0", "--aip-seeds", "2"], "--aip-seeds"),
    (["fidelity", "--env", "warehouse_v0", "--local", "arrays"], "--local arrays"),
    (["fidelity", "--env", "sumo_net_v0", "--net", "cologne1", "--local", "cells"], "--local"),
    (["fidelity", "--env", "warehouse_v0", "--predictor", "on-policy-autoregressive", "--aip-influence-lags", "0"],
     "--aip-influence-lags"),
    (["fidelity", "--env", "warehouse_v0", "--predictor", "on-policy", "--aip-influence-lags", "3"],
     "--aip-influence-lags"),
    (["fidelity", "--env", "warehouse_v0", "--predictor", "on-policy", "--aip-clock-horizon", "-1"],
     "--aip-clock-horizon"),
    (["fidelity", "--env", "warehouse_v0", "--aip-clock-horizon", "100"], "--aip-clock-horizon"),
    (["fidelity", "--env", "warehouse_v0", "--predictor", "on-policy", "--collect-steps", "0"], "--collect-steps"),
    (["evaluate", "--env", "warehouse_v0", "--policy", "random", "--out", "{d}/adir"], "is a folder"),
    (["evaluate", "--env", "warehouse_v0", "--policy", "random", "--frame-stack", "-1"], "--frame-stack"),
    (["evaluate", "--env", "warehouse_v0", "--policy", "random", "--frame-stack", "0"], "--frame-stack"),
    (["collect", "--env", "warehouse_v0", "--agent", "robot_20", "--out", "{d}/adir"], "is a folder"),
    (["collect", "--env", "warehouse_v0", "--agent", "robot_20", "--options", '{"bad": 1}', "--out", "{d}/c.npz"],
     "bad"),
    (["collect", "--env", "warehouse_v0", "--agent", "robot_20", "--seed", "-1", "--out", "{d}/c.npz"], "seed"),
    (["train-aip", "--env", "warehouse_v0", "--out", "{d}/adir"], "is a folder"),
    (["train-aip", "--data", "{d}/trunc.npz", "--out", "{d}/o.pt"], "not an ials_zoo influence data set"),
    (["train-aip", "--data", "{d}/random.npz", "--out", "{d}/o.pt"], "not an ials_zoo influence data set"),
    (["train-aip", "--data", "{d}/pickled.npz", "--out", "{d}/o.pt"], "never loaded"),
    (["train-aip", "--data", "{d}/missing.npz", "--out", "{d}/o.pt"], "not found"),
    (["train-aip", "--env", "warehouse_v0", "--epochs", "0", "--out", "{d}/o.pt"], "--epochs"),
    (["train-aip", "--env", "warehouse_v0", "--batch-size", "0", "--out", "{d}/o.pt"], "--batch-size"),
    (["train-aip", "--env", "warehouse_v0", "--lr", "nan", "--out", "{d}/o.pt"], "--lr"),
    (["train-aip", "--env", "warehouse_v0", "--lr-schedule", "step", "--out", "{d}/o.pt"], "--lr-schedule"),
    (["train-aip", "--env", "warehouse_v0", "--influence-lags", "3", "--out", "{d}/o.pt"], "--influence-lags"),
    (["train-aip", "--env", "warehouse_v0", "--autoregressive", "--influence-lags", "0", "--out", "{d}/o.pt"],
     "--influence-lags"),
    (["train", "ppo_single", "--env", "warehouse_v0", "--batch-size", "0", "--out-dir", "{d}/r"], "--batch-size"),
    (["train", "ppo_single", "--env", "warehouse_v0", "--learning-rate", "-1", "--out-dir", "{d}/r"],
     "--learning-rate"),
    (["train", "ppo_single", "--env", "warehouse_v0", "--learning-rate", "nan", "--out-dir", "{d}/r"],
     "--learning-rate"),
    (["train", "ppo_single", "--env", "warehouse_v0", "--out-dir", "{d}/afile"], "is a file"),
    (["train", "dials", "--env", "warehouse_v0", "--refresh", "0", "--out-dir", "{d}/r"], "--refresh"),
    (["train", "dials", "--env", "warehouse_v0", "--agents", "robot_99", "--out-dir", "{d}/r"], "robot_99"),
    (["train", "dials", "--env", "warehouse_v0", "--local", "arrays", "--out-dir", "{d}/r"], "--local"),
    (["train", "dials", "--env", "sumo_net_v0", "--local", "cells", "--out-dir", "{d}/r"], "--local"),
    (["train", "ippo", "--env", "nowhere_v0", "--out-dir", "{d}/r"], "nowhere_v0"),
    (["train", "idqn", "--env", "warehouse_v0", "--eps-end", "1.5", "--out-dir", "{d}/r"], "--eps-end"),
    (["train", "idqn", "--env", "warehouse_v0", "--buffer-size", "0", "--out-dir", "{d}/r"], "--buffer-size"),
    (["train", "idqn", "--env", "warehouse_v0", "--buffer-size", "100000000", "--out-dir", "{d}/r"],
     "--buffer-size"),
    (["train", "idqn", "--env", "warehouse_v0", "--learning-rate", "nan", "--out-dir", "{d}/r"], "--learning-rate"),
    (["train", "idqn", "--env", "warehouse_v0", "--total-timesteps", "50", "--out-dir", "{d}/r"],
     "less than one episode"),
    (["train", "idqn", "--env", "warehouse_v0", "--env-options", '{"gamma": 1}', "--out-dir", "{d}/r"], "gamma"),
    (["reproduce", "--experiments", "dials", "--dials-variants", "bogus", "--dry-run"], "bogus"),
    (["train", "mplight", "--env", "warehouse_v0", "--out-dir", "{d}/r"], "no pressure observation"),
    (["train", "mplight", "--env", "sumo_net_v0", "--env-options", '{"reward": "wait"}', "--out-dir", "{d}/r"],
     "MPLight sets reward itself"),
    (["train", "mplight", "--env", "sumo_net_v0", "--buffer-size", "5", "--batch-size", "4", "--learning-starts", "4",
      "--out-dir", "{d}/r"], "--buffer-size"),
    (["train", "idqn", "--env", "sumo_net_v0", "--train-reward", "speed", "--out-dir", "{d}/r"], "wait_scaled"),
    (["train", "idqn", "--env", "warehouse_v0", "--train-reward", "wait", "--out-dir", "{d}/r"], "one reward"),
    (["train", "idqn", "--env", "sumo_net_v0", "--env-options", '{"reward": "wait"}', "--train-reward", "wait",
      "--out-dir", "{d}/r"], "scores the policy"),
    (["train", "mplight", "--env", "sumo_net_v0", "--train-reward", "wait", "--out-dir", "{d}/r"], "its own"),
    (["train", "ippo", "--env", "sumo_net_v0", "--train-reward", "speed", "--out-dir", "{d}/r"], "wait_scaled"),
    (["train", "shared_ppo", "--env", "warehouse_v0", "--recurrent-hidden", "8", "--out-dir", "{d}/r"],
     "--recurrent-hidden"),
    (["train", "shared_ppo", "--env", "sumo_net_v0", "--imitate", "maxwave", "--out-dir", "{d}/r"], "--imitate"),
    (["train", "shared_ppo", "--env", "sumo_net_v0", "--imitate", "fixed", "--out-dir", "{d}/r"], "cannot be read"),
    (["train", "ippo", "--env", "sumo_net_v0", "--imitate-episodes", "2", "--out-dir", "{d}/r"], "needs --imitate"),
    (["train", "ippo", "--env", "sumo_net_v0", "--imitate", "greedy", "--imitate-episodes", "0", "--out-dir",
      "{d}/r"], "--imitate-episodes"),
    (["train", "ippo", "--env", "sumo_net_v0", "--imitate", "greedy", "--frame-stack", "2", "--out-dir", "{d}/r"],
     "--frame-stack 1"),
    (["evaluate", "--env", "sumo_net_v0", "--joint", "--policy", "rule:maxwave"], "rule:greedy"),
    (["evaluate", "--env", "sumo_net_v0", "--policy", "rule:greedy"], "--joint"),
]


@pytest.mark.parametrize("argv, words", CASES, ids=[" ".join(c[0][:2]) + f" #{i}" for i, c in enumerate(CASES)])
def test_bad_input_is_one_clear_error_before_any_work(files, capsys, argv, words):
    argv = [a.replace("{d}", str(files)) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    command = argv[0]
    assert f"ials-zoo {command}" in err and words in err and "Traceback" not in err
    assert not (files / "r").exists() and not (files / "o.pt").exists() and not (files / "c.npz").exists()


@pytest.mark.parametrize("argv, words", [(["train", "iqdn", "--env", "warehouse_v0"], "invalid choice: 'iqdn'"),
                                         (["train", "idqn", "--env", "warehouse_v0", "--n-epochs", "3"], "--n-epochs")])
def test_an_unknown_learner_or_an_option_it_does_not_take_is_refused_by_argparse(tmp_path, capsys, argv, words):
    with pytest.raises(SystemExit) as stop:
        main(argv + ["--out-dir", str(tmp_path / "r")])
    assert stop.value.code == 2 and words in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_a_bug_shows_its_traceback_while_bad_input_does_not(monkeypatch, capsys):
    """Only ``ials_zoo.errors.BadInput`` (what our checks raise) is printed as one line with
    exit status 2; a ValueError from numpy inside a command is a bug and propagates."""
    import numpy as np

    from ials_zoo.commands import evaluate
    from ials_zoo.errors import BadInput

    def bug(args):
        return np.zeros(-1)  # numpy's own ValueError

    monkeypatch.setattr(evaluate, "run", bug)
    with pytest.raises(ValueError, match="negative dimensions"):
        main(["evaluate", "--env", "warehouse_v0", "--policy", "random"])

    def bad(args):
        raise BadInput("--policy: nothing there")

    monkeypatch.setattr(evaluate, "run", bad)
    assert main(["evaluate", "--env", "warehouse_v0", "--policy", "random"]) == 2
    assert capsys.readouterr().err.strip() == "ials-zoo evaluate: --policy: nothing there"


def test_a_dead_or_stopped_worker_ends_a_command_in_one_line_with_exit_1(monkeypatch, capsys):
    from ials_zoo.commands import evaluate
    from ials_zoo.runtime.processes import WorkerError

    def stopped(args):
        raise WorkerError("DIALS worker 1 (pid 123, agents robot_18..robot_35) is stopped (SIGSTOP or a debugger: "
                          "process state T)", kind="stopped")

    monkeypatch.setattr(evaluate, "run", stopped)
    assert main(["evaluate", "--env", "warehouse_v0", "--policy", "random"]) == 1
    err = capsys.readouterr().err
    assert err.strip() == ("ials-zoo evaluate: DIALS worker 1 (pid 123, agents robot_18..robot_35) is stopped "
                           "(SIGSTOP or a debugger: process state T)") and "Traceback" not in err


def test_a_sumo_error_ends_a_baseline_run_in_one_line_on_both_entry_points(monkeypatch, capsys):
    """``ials-zoo train`` and ``python -m baselines.<name>`` (run_cli) report a run failure
    alike: one line, exit 1."""
    import sys

    from ials_zoo.baselines import arguments, ippo
    from ials_zoo.sumo.lease import SimulationError

    def fails(args=None):
        raise SimulationError("SUMO error (TraCIException): the network broke")

    monkeypatch.setattr(ippo, "main", fails)
    monkeypatch.setattr(sys, "argv", ["ippo", "--env", "warehouse_v0"])
    assert arguments.run_cli(ippo) == 1
    assert capsys.readouterr().err.strip() == "ippo: SUMO error (TraCIException): the network broke"


def test_train_errors_name_the_flag_and_help_shows_each_default_once(capsys):
    """A baseline's check says ``total_timesteps``; the command line says ``--total-timesteps``.
    A help text that already states its default gets no second ``(default: None)``."""
    from ials_zoo.cli import main

    assert main(["train", "ippo", "--env", "warehouse_v0", "--total-timesteps", "0"]) == 2
    assert "ials-zoo train: --total-timesteps must be >= 1, got 0" in capsys.readouterr().err
    assert main(["train", "dials", "--env", "warehouse_v0", "--checkpoint-every", "-5", "--out-dir", "/nonexistent/x"]) == 2
    assert "ials-zoo train: --checkpoint-every must be >= 0 (0: at evaluations only), got -5" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["train", "dials", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "(default: None)" not in text and "(default: 0)" in text
    # every domain DIALS trains on has its defaults in the help, the real networks included
    assert "sumo_net_v0 720, traffic_grid_v0 10,000, warehouse_v0 10,000" in text
