"""Trust, round two: each test reproduces a way an entry could lie or a file could break the
board (issue 18), and fails on the code before the fix."""

from __future__ import annotations

import copy
import json
import multiprocessing
import os
import time

import numpy as np
import pytest

from ials_zoo import leaderboard as lb
from ials_zoo.evaluation import evaluate
from ials_zoo.leaderboard.validate import ResultError
from ials_zoo.policy import PolicyFileError, PolicyNetwork, load_policy_file, save_policy
from ials_zoo.stats import bootstrap_interval

ENV, AGENT = "warehouse_v0", "robot_20"


@pytest.fixture(scope="module")
def scripted():
    return lb.reference_result(ENV, AGENT, "scripted", episodes=20)


@pytest.fixture
def board(tmp_path):
    d = tmp_path / "leaderboard"
    (d / "results").mkdir(parents=True)
    return d


def _write(folder, data, name="r.json"):
    p = folder / name
    p.write_text(data if isinstance(data, str) else json.dumps(data))
    return p


def _trained_policy(folder, training: dict | None, seed=0, name="policy.safetensors", algorithm="ppo_single"):
    """A policy file as our trainers write it: weights plus a header with the training record."""
    rng = np.random.default_rng(seed)
    layers = [(rng.normal(size=(1, 37, 8)).astype(np.float32), np.zeros((1, 8), np.float32)),
              (rng.normal(size=(1, 8, 4)).astype(np.float32), np.zeros((1, 4), np.float32))]
    meta = {"env_id": ENV, "seed": seed}
    if training is not None:
        meta.update(algorithm=algorithm, training=training)
    return save_policy(PolicyNetwork([AGENT], 37, 4, layers, metadata=meta), folder / name)


TRAINING = {"simulator": "gs", "aip": None, "seeds": [0], "env_steps": 4096, "wall_clock_seconds": 12.5,
            "aip_seconds": 0.0, "hyperparameters": {}}


def _model_result(folder, training=TRAINING, claimed=None, episodes=20):
    path = _trained_policy(folder, training)
    ev = evaluate(ENV, AGENT, str(path), episodes=episodes)
    return lb.make_result([ev], algorithm="ppo_single", training_seeds=[0], training=dict(claimed or training))


def _recompute(result):
    """A forger's result: every mean and interval recomputed, so that validate accepts it."""
    for s in result["scores"]:
        s["mean"], s["ci_low"], s["ci_high"] = bootstrap_interval(s["returns"])
    result["score"] = lb.overall_score(result["scores"])
    return result


# -- 1. an entry is what it claims to be ------------------------------------------------------

def test_a_reference_cannot_pose_as_a_trained_entry(scripted):
    forged = copy.deepcopy(scripted)
    forged["algorithm"] = "DIALS (ours)"
    forged["training"] = dict(TRAINING, env_steps=1000, wall_clock_seconds=3)
    forged["trained_agents"] = [AGENT]
    with pytest.raises(ResultError, match="reference"):
        lb.validate_result(forged)


def test_a_training_record_is_bound_to_its_policy_file(tmp_path, board):
    faked = _model_result(tmp_path, claimed=dict(TRAINING, env_steps=1))
    with pytest.raises(ResultError, match="env_steps"):
        lb.submit(_write(tmp_path, faked), board)
    honest = _model_result(tmp_path)
    entry = lb.load_result(lb.submit(_write(tmp_path, honest, "h.json"), board))
    assert entry["provenance"] == "header-agrees"
    assert all(r["ok"] for r in lb.verify(board / "results" / next(iter(os.listdir(board / "results"))),
                                          directory=board))


def test_policies_our_trainers_did_not_make_are_labelled_external(tmp_path, board):
    result = _model_result(tmp_path, training=None, claimed=TRAINING)
    entry = lb.load_result(lb.submit(_write(tmp_path, result), board))
    assert entry["provenance"] == "external"
    assert "external: training claims unverified" in lb.show(board)


def test_a_forged_score_is_refused_at_submit(tmp_path, board, scripted):
    forged = copy.deepcopy(scripted)
    forged["scores"][0]["returns"] = [r + 5.0 for r in forged["scores"][0]["returns"]]
    lb.validate_result(_recompute(forged))  # a consistent file ...
    with pytest.raises(ResultError, match="re-measured"):  # ... that the GS does not reproduce
        lb.submit(_write(tmp_path, forged), board)
    assert not os.listdir(board / "results")


@pytest.mark.parametrize("options", [{"seeds": [1]}, {"progress": True}, {"learners": ["robot_0"]},
                                     {"deterministic": True}, {"policy": "x"}, {"agent": AGENT},
                                     {"env_id": ENV}, {"episodes": 3}, {"render_mode": "human"}])
def test_evaluation_options_are_the_domains_gs_options(scripted, options):
    forged = copy.deepcopy(scripted)
    forged["evaluation"]["options"] = options
    forged["evaluation"]["protocol"] = "variant"
    with pytest.raises(ResultError, match="not a GS option"):
        lb.validate_result(forged)


def test_a_policy_file_must_load_as_a_policy(tmp_path, board):
    from ials_zoo.evaluation import sha256_file

    result = _model_result(tmp_path)
    fake = tmp_path / "passwd"
    fake.write_text("root:x:0:0:root:/root:/bin/bash\n")
    result["scores"][0]["policy_file"] = str(fake)
    result["scores"][0]["policy_sha256"] = sha256_file(fake)
    with pytest.raises(ResultError, match="not a policy file"):
        lb.submit(_write(tmp_path, result), board)
    assert not list((board).rglob("*.safetensors"))


def test_an_sb3_entry_is_converted_and_verifies_from_the_board(tmp_path, board):
    from stable_baselines3 import PPO

    from ials_zoo.influence.ials import make_ials_vec_env

    venv = make_ials_vec_env(ENV, AGENT, n_envs=2, predictor="uniform", seed=0)
    model = PPO("MlpPolicy", venv, n_steps=8, batch_size=16, device="cpu", policy_kwargs={"net_arch": [16]})
    model.save(tmp_path / "model.zip")
    (tmp_path / "model.meta.json").write_text(json.dumps({"env_id": ENV, "agent": AGENT, "frame_stack": 1,
                                                         "sb3_class": "PPO"}))
    ev = evaluate(ENV, AGENT, str(tmp_path / "model.zip"), episodes=20)
    result = lb.make_result([ev], algorithm="ppo_single", training_seeds=[0], training=TRAINING)
    entry_path = lb.submit(_write(tmp_path, result), board)
    entry = lb.load_result(entry_path)
    assert entry["scores"][0]["policy_file"].endswith(".safetensors") and entry["provenance"] == "external"
    load_policy_file(board / entry["scores"][0]["policy_file"])
    (tmp_path / "model.zip").unlink()  # the board alone re-scores it
    assert all(r["ok"] for r in lb.verify(entry_path, directory=board))
    assert not [p for p in (board / "policies").iterdir() if p.name.startswith(".")]


# -- 2. no entry and no file breaks the board ------------------------------------------------

def test_huge_integers_and_deep_nesting_are_refused_by_name(tmp_path, scripted):
    huge = json.dumps(scripted).replace('"notes": ""', '"notes": "", "x": 1' + "0" * 400)
    with pytest.raises(ResultError, match="does not fit a float"):
        lb.load_result(_write(tmp_path, huge))
    returns = copy.deepcopy(scripted)
    returns["scores"][0]["returns"] = ["HUGE"] * 20
    text = json.dumps(returns).replace('"HUGE"', "1" + "0" * 400)
    with pytest.raises(ResultError, match="does not fit a float"):
        lb.load_result(_write(tmp_path, text, "r2.json"))
    deep = "[" * 100_000 + "]" * 100_000
    with pytest.raises(ResultError, match="nested"):
        lb.load_result(_write(tmp_path, deep, "r3.json"))


def test_user_text_cannot_break_or_rewrite_the_rendered_board(tmp_path, board):
    training = dict(TRAINING, simulator="gs | injected | row |\n| fake | 999 |", wall_clock_seconds=1e300)
    policy = _trained_policy(tmp_path, training, algorithm="$\\foo$")
    result = lb.make_result([evaluate(ENV, AGENT, str(policy), episodes=20)], algorithm="$\\foo$",
                            training_seeds=[0], training=training)
    lb.submit(_write(tmp_path, result), board)
    readme = lb.render(board).read_text()  # mathtext would fail on $\foo$; 1e300 s is just long
    assert "| fake | 999 |" not in readme and "\\| injected" in readme
    assert "$\\foo$" in lb.show(board)


def test_links_fifos_and_devices_on_the_board_are_named_and_skipped(tmp_path, board, scripted):
    lb.submit(_write(tmp_path, scripted), board)
    results = board / "results"
    os.symlink("/dev/zero", results / "zero.json")
    os.mkfifo(results / "fifo.json")
    secret = tmp_path / "secret.txt"
    secret.write_text("API_KEY=hunter2")
    os.symlink(secret, board / "writeup.md")
    start = time.monotonic()
    table = lb.show(board)
    readme = lb.render(board).read_text()
    assert time.monotonic() - start < 30  # a fifo is never waited on
    assert "skipped zero.json" in table and "skipped fifo.json" in table and "scripted" in table
    assert "hunter2" not in readme and "writeup.md" in readme and "scripted" in readme


def test_a_result_file_of_huge_numbers_or_deep_json_on_the_board_is_skipped_by_name(board, scripted):
    """Placed straight into results/ (not submitted): ``training.wall_clock_seconds = 10**400``
    and JSON nested 100,000 deep are named and skipped by show, render and validate; the
    rest of the board is still shown."""
    lb.submit(_write(board.parent, scripted), board)
    results = board / "results"
    huge = copy.deepcopy(scripted)
    huge["training"] = dict(TRAINING, wall_clock_seconds="HUGE")
    (results / "huge.json").write_text(json.dumps(huge).replace('"HUGE"', "1" + "0" * 400))
    (results / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    table = lb.show(board)
    readme = lb.render(board).read_text()
    assert "skipped huge.json" in table and "skipped deep.json" in table and "scripted" in table
    assert "scripted" in readme
    with pytest.raises(ResultError, match="does not fit a float"):
        lb.load_result(results / "huge.json")


def test_policy_and_aip_files_with_deep_or_wrong_headers_are_refused(tmp_path):
    import torch

    from ials_zoo.influence.files import load_predictor_set
    from ials_zoo.policy import HEADER_KEY

    path = _trained_policy(tmp_path, TRAINING)
    from safetensors.numpy import load_file, save_file

    tensors = load_file(path)
    from safetensors import safe_open

    with safe_open(str(path), framework="np") as f:
        header = json.loads(f.metadata()[HEADER_KEY])
    for change, match in (({"deep": "[" * 100_000 + "]" * 100_000}, "nested"), ({"n_actions": 4.7}, "integer")):
        bad = dict(header)
        for k, v in change.items():
            bad[k] = v
        text = json.dumps(bad)
        if "deep" in change:
            text = text.replace('"' + change["deep"] + '"', change["deep"])
        save_file(tensors, tmp_path / "bad.safetensors", metadata={HEADER_KEY: text})
        with pytest.raises(PolicyFileError, match=match):
            load_policy_file(tmp_path / "bad.safetensors")
    save_file({k: v.astype(np.int64) for k, v in tensors.items()}, tmp_path / "int.safetensors",
              metadata={HEADER_KEY: json.dumps(header)})
    with pytest.raises(PolicyFileError, match="floating point"):
        load_policy_file(tmp_path / "int.safetensors")
    # AIP sets: a deep metadata_json, members that are not a list, a future format, duplicates
    from ials_zoo.influence.multi import shipped_set_path

    payload = torch.load(shipped_set_path(ENV), weights_only=True)
    cases = [({"members": 5}, "members"), ({"format_version": 99}, "format version"),
             ({"members": payload["members"][:1] * 2}, "two members"),
             ({"members": [dict(payload["members"][0], metadata_json="[" * 100_000 + "]" * 100_000)]}, "nested")]
    for change, match in cases:
        torch.save(dict(payload, **change), tmp_path / "set.pt")
        with pytest.raises(ValueError, match=match):
            load_predictor_set(tmp_path / "set.pt")


# -- 4. concurrency -------------------------------------------------------------------------

def _submit_quietly(path, board, queue):
    """Submit with a slow look at the board: both processes look before either writes, the
    window in which an unlocked submit accepts both."""
    import ials_zoo.leaderboard.store as store

    original = store.load_entries

    def slow(*args, **kwargs):
        out = original(*args, **kwargs)
        time.sleep(1.0)
        return out

    store.load_entries = slow
    try:
        lb.submit(path, board)
        queue.put("accepted")
    except ResultError as exc:
        queue.put(f"rejected: {exc}")


def test_two_submissions_of_one_evaluation_at_once_accept_exactly_one(tmp_path, board, scripted):
    paths = []
    for i in range(2):
        r = dict(copy.deepcopy(scripted), notes=f"try {i}")
        paths.append(_write(tmp_path, r, f"r{i}.json"))
    ctx = multiprocessing.get_context("fork")
    for _ in range(2):
        for p in (board / "results").iterdir():
            p.unlink()
        queue = ctx.Queue()
        procs = [ctx.Process(target=_submit_quietly, args=(p, board, queue)) for p in paths]
        for p in procs:
            p.start()
        for p in procs:
            p.join(120)
        answers = sorted(queue.get(timeout=5) for _ in procs)
        assert answers[0] == "accepted" and "duplicate" in answers[1], answers
        assert len(os.listdir(board / "results")) == 1


# -- 5. small silent acceptances --------------------------------------------------------------

@pytest.mark.parametrize("env_id", ["warehouse_v0", "traffic_grid_v0"])
def test_reset_options_are_never_silently_ignored(env_id):
    """Not a dict: refused. A key the env does not know (a typo of a GS option): a warning that
    names it. (Refusing it would fail PettingZoo's own API test, which resets with
    ``options={"options": 1}``.)"""
    from ials_zoo.core.domains import get_domain

    small = {"robots": (2, 2)} if env_id == "warehouse_v0" else {"grid": (2, 2)}
    env = get_domain(env_id).parallel_env(**small)
    try:
        env.reset(seed=0, options={})
        for bad in ("notadict", []):
            with pytest.raises(TypeError, match="reset options must be a dict"):
                env.reset(seed=0, options=bad)
        with pytest.warns(UserWarning, match="itme_lifetime"):
            env.reset(seed=0, options={"itme_lifetime": 3})
    finally:
        env.close()


def test_data_sets_of_nan_d_sets_or_fractional_influences_are_refused(tmp_path):
    from ials_zoo.influence.dataset import InfluenceDataset, collect

    ds = collect(ENV, "robot_0", steps=200, seed=0, gs_options={"robots": (2, 2)}, progress=False)
    nan = {k: v.astype(np.float64) for k, v in ds.dsets.items()}
    nan["dset"][0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="bits"):
        InfluenceDataset(ds.region, nan, ds.influences, ds.metadata)
    with pytest.raises(ValueError, match="whole class numbers"):
        InfluenceDataset(ds.region, ds.dsets, ds.influences + 0.5, ds.metadata)


def test_the_multi_agent_ials_refuses_a_string_of_agents_and_unknown_predictors():
    from ials_zoo.influence.multi import make_ials_parallel_env

    with pytest.raises(TypeError, match="list of agent ids"):
        make_ials_parallel_env("warehouse_v0", agents="robot_0", predictor="uniform", robots=(2, 2))
    with pytest.raises(ValueError, match="robot_9"):
        make_ials_parallel_env("warehouse_v0", agents=["robot_0"], robots=(2, 2),
                               predictor={"robot_0": "uniform", "robot_9": "uniform"})


def _claim_in_child(path, queue, slow=False):
    import ials_zoo.baselines.runs as runs

    if slow:  # a slow start after looking at the folder: both runs look before either writes
        original = runs.remove_stale_temporaries

        def remove_stale_temporaries(*args, **kwargs):
            time.sleep(1.0)
            return original(*args, **kwargs)

        runs.remove_stale_temporaries = remove_stale_temporaries
    try:
        run = runs.RunFolder(path)
        queue.put("claimed")
        time.sleep(2.0)  # still running while the other one tries
        run.release()
    except ValueError as exc:
        queue.put(str(exc))


def test_two_training_runs_cannot_share_an_out_dir(tmp_path):
    """Two runs start on one empty folder at the same moment: one claims it, the other is
    refused at once (a lock held for the run's life); once the first ends the folder is free
    to resume or overwrite."""
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    children = [ctx.Process(target=_claim_in_child, args=(tmp_path / "run", queue, True)) for _ in range(2)]
    for c in children:
        c.start()
    for c in children:
        c.join(30)
    answers = [queue.get(timeout=5) for _ in children]
    assert answers.count("claimed") == 1 and any("in use by another run" in a for a in answers), answers


def test_ctrl_c_while_starting_prints_no_traceback(tmp_path):
    """SIGINT at several moments of a command's start-up (0.25-2.5 s: importing the package,
    which takes about 0.6 s and more on a loaded machine, the parser, the baseline's imports,
    the workers' spawn): the command ends interrupted (130) and no traceback, from itself or
    from a half-started worker. The quiet exit is installed as the package starts importing,
    so only Python's own start, tens of milliseconds, is left to its handler: the earliest
    moment is a quarter of a second so that a load of 4 on 2 cores does not reach it."""
    import signal
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "ials_zoo.cli", "train", "dials", "--env", "warehouse_v0", "--agents",
           "robot_0,robot_1", "--env-options", '{"robots": [2, 2]}', "--total-timesteps", "4096",
           "--samples-per-update", "128", "--batch-size", "64", "--workers", "2", "--no-progress"]
    for i, delay in enumerate((0.25, 0.4, 0.6, 1.0, 1.5, 2.5)):
        proc = subprocess.Popen(cmd + ["--out-dir", str(tmp_path / f"r{i}")], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, start_new_session=True)
        time.sleep(delay)
        os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole process group
        _, err = proc.communicate(timeout=60)
        assert "Traceback" not in err, (delay, err)
        # 130, or killed by the SIGINT itself (-2) when the interrupt lands as Python hands the
        # exit status back: both say "interrupted"; 0 if it had already finished
        assert proc.returncode in (130, -signal.SIGINT, 0), (delay, proc.returncode, err)
