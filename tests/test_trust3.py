"""Trust, round three (issue 34): each test reproduces a way a run, an entry or a file could
mislead, and fails on the code before the fix."""

from __future__ import annotations

import json
import shutil

import pytest

from ials_zoo.errors import BadInput

ENV = "warehouse_v0"
OPTIONS = {"robots": [2, 2]}
AGENTS = ["robot_0", "robot_1", "robot_2", "robot_3"]
MULTI = dict(env_id=ENV, agents=",".join(AGENTS), env_options=json.dumps(OPTIONS), n_envs=2, samples_per_update=128,
             batch_size=64, n_epochs=2, hidden="16", eval_episodes=1, final_eval_episodes=2, progress=False,
             total_timesteps=512, eval_every=256, checkpoint_every=0)  # checkpoints at evaluations only
RUNS = {
    "ippo": MULTI,
    "dials": dict(MULTI, refresh="384", collect_steps=200, aip_epochs=1, workers=0),
    "ppo_single": dict(env_id=ENV, env_options=json.dumps(OPTIONS), agent="robot_0", total_timesteps=512, n_envs=2,
                       n_steps=64, batch_size=64, n_epochs=2, net_arch="16", eval_every=256, eval_episodes=1,
                       final_eval_episodes=2, progress=False),
}


class Crash(RuntimeError):
    pass


def _killed_after_first_checkpoint(monkeypatch, module, out, seed):
    """A run of ``module`` that dies at its second GS evaluation: one checkpoint (at step 0)."""
    from ials_zoo.baselines import driver

    real, seen = driver._curve_point, []

    def point(*args, **kwargs):
        if seen:
            raise Crash("killed")
        seen.append(real(*args, **kwargs))
        return seen[-1]

    monkeypatch.setattr(driver, "_curve_point", point)
    with pytest.raises(Crash):
        module.main(module.Args(**RUNS[module.__name__.rsplit(".", 1)[1]], seed=seed, out_dir=str(out)))
    monkeypatch.undo()


# -- 2. resumes bound to their run ----------------------------------------------------------

@pytest.mark.parametrize("name", ["ippo", "dials", "ppo_single"])
def test_another_runs_checkpoint_is_refused_by_name(tmp_path, monkeypatch, name):
    """Seed 1's checkpoint files copied into seed 0's folder (killed at the same step): the
    resume of seed 0 is refused, naming both seeds, instead of a seed-0 result with seed 1's
    weights; only checkpoint.pt copied is refused as well. The checkpoint holds the curve point
    of its own step (a driver that checkpoints before adding it fails here)."""
    import importlib

    module = importlib.import_module(f"ials_zoo.baselines.{name}")
    mine, theirs = tmp_path / "seed0", tmp_path / "seed1"
    _killed_after_first_checkpoint(monkeypatch, module, mine, 0)
    _killed_after_first_checkpoint(monkeypatch, module, theirs, 1)
    info = json.loads((mine / "checkpoint.json").read_text())
    assert info["curve"] and info["curve"][-1]["env_steps"] == info["steps"] == 0
    for files in (["checkpoint.pt"], ["checkpoint.pt", "checkpoint.json"]):
        saved = {f: (mine / f).read_bytes() for f in files}
        for f in files:
            shutil.copyfile(theirs / f, mine / f)
        naming = r"belongs to another run \(written by a run of seed 1; this run's seed is 0\)" if len(files) == 2 else \
            r"belongs to another run: its run id"
        with pytest.raises(BadInput, match=naming):
            module.main(module.Args(**RUNS[name], seed=0, out_dir=str(mine), resume=True))
        assert not (mine / "result.json").exists()
        for f, data in saved.items():
            (mine / f).write_bytes(data)
    module.main(module.Args(**RUNS[name], seed=0, out_dir=str(mine), resume=True))  # its own: resumes
    assert (mine / "result.json").is_file()


def test_a_checkpoint_json_that_is_not_an_object_is_refused_by_name(tmp_path, monkeypatch):
    from ials_zoo.baselines import ippo

    out = tmp_path / "run"
    _killed_after_first_checkpoint(monkeypatch, ippo, out, 0)
    for text in ("[1, 2]", '{"steps": "x", "curve": [], "clock": 0}', "[" * 100_000 + "]" * 100_000):
        (out / "checkpoint.json").write_text(text)
        with pytest.raises(BadInput, match="checkpoint"):
            ippo.main(ippo.Args(**MULTI, out_dir=str(out), resume=True))


@pytest.mark.parametrize("bad", [{"env_options": json.dumps(dict(OPTIONS, itme_lifetime=3))},
                                 {"aip": "not-an-aip-set"}])
def test_bad_input_found_at_the_start_leaves_no_run_behind(tmp_path, bad):
    """A typo in the GS options, or an AIP set that is not one: the message names it, and the
    folder is left as it was, so that the corrected command runs without --overwrite."""
    from ials_zoo.baselines import dials

    out = tmp_path / "d"
    if "aip" in bad:
        (tmp_path / "aips.pt").write_bytes(b"not an AIP set")
        bad = {"aip": str(tmp_path / "aips.pt")}
    with pytest.raises(BadInput):
        dials.main(dials.Args(**dict(RUNS["dials"], **bad, total_timesteps=256), out_dir=str(out)))
    assert not out.exists()
    dials.main(dials.Args(**dict(RUNS["dials"], total_timesteps=256), out_dir=str(out)))
    assert (out / "result.json").is_file()


# -- 3. every parser of a file someone else made has limits ----------------------------------

DEEP = "[" * 100_000 + "]" * 100_000


@pytest.fixture(scope="module")
def sb3_model(tmp_path_factory):
    from stable_baselines3 import PPO

    from ials_zoo.influence.ials import make_ials_vec_env

    folder = tmp_path_factory.mktemp("sb3")
    venv = make_ials_vec_env(ENV, "robot_20", n_envs=2, predictor="uniform", seed=0)
    PPO("MlpPolicy", venv, n_steps=8, batch_size=16, device="cpu", policy_kwargs={"net_arch": [16]}).save(
        folder / "model.zip")
    return folder / "model.zip"


GOOD_META = {"env_id": ENV, "agent": "robot_20", "frame_stack": 1, "sb3_class": "PPO"}


@pytest.mark.parametrize("sidecar,match", [
    (DEEP, "nested"), ("[1, 2]", "JSON object"), (dict(GOOD_META, frame_stack="x"), "frame_stack"),
    (dict(GOOD_META, frame_stack=10**9), "frame_stack"), (dict(GOOD_META, agent=5), "agent"),
    (dict(GOOD_META, agent="robot_99"), "agent"), (dict(GOOD_META, env_id=["x"]), "env_id")])
def test_an_sb3_sidecar_is_read_with_limits_and_checked_before_use(tmp_path, sb3_model, sidecar, match, capsys):
    """``evaluate --policy model.zip`` and ``leaderboard convert`` on a sidecar 100,000 levels
    deep, a JSON list, a frame_stack that is no number, an agent that is no agent: one line,
    exit 2, no traceback, and no policy file written."""
    from ials_zoo.cli import main
    from ials_zoo.evaluation import load_model

    model = tmp_path / "model.zip"
    shutil.copyfile(sb3_model, model)
    (tmp_path / "model.meta.json").write_text(sidecar if isinstance(sidecar, str) else json.dumps(sidecar))
    with pytest.raises(BadInput, match=match):
        load_model(model)
    out = tmp_path / "policy.safetensors"
    assert main(["leaderboard", "convert", str(model), "--out", str(out)]) == 2
    assert main(["evaluate", "--env", ENV, "--agent", "robot_20", "--policy", str(model), "--episodes", "1"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and match in err and not out.exists()


@pytest.mark.parametrize("metadata,match", [(DEEP, "nested"), ("[1]", "JSON object"), ('"text"', "JSON object")])
def test_a_data_sets_metadata_is_read_with_limits(tmp_path, metadata, match):
    import numpy as np

    from ials_zoo.influence.dataset import InfluenceDataset

    path = tmp_path / "data.npz"
    np.savez(path, dset=np.zeros((2, 3), np.float32), full=np.zeros((2, 3), np.float32),
             influences=np.zeros((2, 1), np.int64), metadata=np.array(metadata))
    with pytest.raises(BadInput, match=match):
        InfluenceDataset.load(path)


# -- 1. a training claim the board can check, not only read ----------------------------------

TINY_IPPO = dict(MULTI, total_timesteps=256, eval_every=256, final_eval_episodes=20)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """Two tiny IPPO runs (seeds 0 and 1) of the 2x2 warehouse, each with its result."""
    from ials_zoo.baselines import ippo

    root = tmp_path_factory.mktemp("trained")
    for seed in (0, 1):
        ippo.main(ippo.Args(**TINY_IPPO, seed=seed, out_dir=str(root / f"s{seed}")))
    return root


def _board(tmp_path):
    board = tmp_path / "board"
    (board / "results").mkdir(parents=True)
    return board


def _rewrite_header(path, **changes):
    """A forger's policy file: the header edited (dotted keys), the weights kept."""
    from safetensors import safe_open
    from safetensors.numpy import load_file, save_file

    from ials_zoo.policy import HEADER_KEY

    with safe_open(str(path), framework="np") as f:
        header = json.loads(f.metadata()[HEADER_KEY])
    for dotted, value in changes.items():
        *parents, leaf = dotted.split(".")
        node = header
        for p in parents:
            node = node[p]
        node[leaf] = value
    save_file(load_file(str(path)), str(path), metadata={HEADER_KEY: json.dumps(header)})


def _forged_entry(tmp_path, trained, weights_of: int, **header):
    """Seed 0's result pointing at ``weights_of``'s weights under a header edited as given,
    its sha256 and scores recomputed: a file that submit accepts."""
    from ials_zoo import leaderboard as lb
    from ials_zoo.evaluation import evaluate_joint, sha256_file

    policy = tmp_path / "forged.safetensors"
    shutil.copyfile(trained / f"s{weights_of}" / "policy.safetensors", policy)
    result = json.loads((trained / "s0" / "result.json").read_text())
    # the forger makes every field submit compares agree (the machine's timings too, since round four)
    _rewrite_header(policy, **{"seed": 0, "training.wall_clock_seconds": result["training"]["wall_clock_seconds"],
                               "training.reference": result["training"]["reference"], **header})
    ev = evaluate_joint(ENV, str(policy), agents=AGENTS, episodes=20, **OPTIONS)
    forged = lb.make_result([ev], algorithm="ippo", training_seeds=[0],
                            training=dict(result["training"], **{k.split(".", 1)[1]: v for k, v in header.items()
                                                                  if k.startswith("training.")}))
    assert forged["scores"][0]["policy_sha256"] == sha256_file(policy)
    path = tmp_path / "forged.json"
    path.write_text(json.dumps(forged))
    return path


def test_an_entry_is_re_trained_bit_for_bit_and_recorded(tmp_path, trained, capsys):
    """The recorded command re-makes seed 0's policy file exactly; --record marks the entry,
    and the board shows it as re-trained. The label submit gives says only that the header and
    the result agree."""
    from ials_zoo import leaderboard as lb
    from ials_zoo.cli import main

    board = _board(tmp_path)
    entry = lb.submit(trained / "s0" / "result.json", board)
    data = lb.load_result(entry)
    assert data["provenance"] == "header-agrees"
    command = data["training"]["reproduce"]["command"]
    assert command.startswith("ials-zoo train ippo ") and "--env-id warehouse_v0" in command and "--seed 0" in command
    assert main(["leaderboard", "verify", "--retrain", "--record", str(entry), "--dir", str(board)]) == 0
    assert "re-made bit for bit" in capsys.readouterr().out
    assert lb.load_result(entry)["retrained"]["seeds"] == [0]
    assert "[re-trained]" in lb.show(board)


@pytest.mark.parametrize("weights_of,header,where", [
    (0, {"training.env_steps": 1}, "header field training.env_steps (256 re-trained, 1 submitted)"),
    (1, {}, "tensor ")])
def test_a_forged_training_claim_is_accepted_by_submit_but_fails_retraining(tmp_path, trained, weights_of, header,
                                                                             where):
    """The reproductions of the issue: a header edited to claim 1 env step (its sha256 and the
    result's env_steps to match), and seed 1's weights under a seed-0 header. Submit takes
    both ('header-agrees' is all it can say); re-training names the first difference."""
    from ials_zoo import leaderboard as lb
    from ials_zoo.baselines.retrain import package_commit, retrain

    board = _board(tmp_path)
    entry = lb.submit(_forged_entry(tmp_path, trained, weights_of, **header), board)
    assert lb.load_result(entry)["provenance"] == "header-agrees"
    (report,) = retrain(entry, directory=board)
    assert not report["ok"] and report["difference"].startswith(where), report
    assert report["entry_commit"] == lb.load_result(entry)["training"]["reproduce"]["commit"]
    assert report["commit"] == package_commit()


@pytest.mark.parametrize("command,match", [
    ("python -c 'import os'", "is not `ials-zoo train"),
    ("ials-zoo train ippo --env-id warehouse_v0 --aip /etc/passwd", "names a file"),
    ("ials-zoo train ippo --env-id warehouse_v0 --out-dir x", "names a file|never does"),
    ("ials-zoo train ippo --no-such-flag 1", "not a valid ippo command"),
    ("ials-zoo train dials --env-id warehouse_v0 --aip x.pt", "names a file"),
    ("ials-zoo train ppo_single --env-id warehouse_v0 --simulator evil.pt", "names a file"),
    ("ials-zoo train ippo --env-id warehouse_v0 --n-envs 100000", "more than the 64"),
    ("ials-zoo train dials --env-id warehouse_v0 --backend ray", "this machine's processes"),
    ("ials-zoo train ippo --env-id sumo_net_v0 --env-options '{\"sumocfg\": \"x\"}'", "not GS options")])
def test_a_recorded_command_is_parsed_never_run_by_name(command, match):
    from ials_zoo.baselines.retrain import parse_command
    from ials_zoo.leaderboard.validate import ResultError

    with pytest.raises(ResultError, match=match):
        parse_command(command, 0)


def test_a_policy_trained_elsewhere_gets_an_external_entry_from_evaluate(tmp_path, monkeypatch, capsys):
    """``evaluate --out`` of a policy file without a training record: refused before any
    episode unless the training claims are given; with them, a result that submit labels
    external."""
    import numpy as np

    from ials_zoo import leaderboard as lb
    from ials_zoo.cli import main
    from ials_zoo.leaderboard import build
    from ials_zoo.policy import PolicyNetwork, save_policy

    rng = np.random.default_rng(0)
    layers = [(rng.normal(size=(1, 37, 8)).astype(np.float32), np.zeros((1, 8), np.float32)),
              (rng.normal(size=(1, 8, 4)).astype(np.float32), np.zeros((1, 4), np.float32))]
    policy = save_policy(PolicyNetwork(["robot_20"], 37, 4, layers, metadata={"env_id": ENV}), tmp_path / "p.safetensors")
    out = tmp_path / "r.json"
    real = build.evaluate

    def no_episodes(*a, **kw):
        raise AssertionError("episodes ran before the refusal")

    monkeypatch.setattr(build, "evaluate", no_episodes)
    assert main(["evaluate", "--policy", str(policy), "--out", str(out), "--no-progress"]) == 2
    assert "--algorithm and --env-steps" in capsys.readouterr().err and not out.exists()
    monkeypatch.setattr(build, "evaluate", real)
    assert main(["evaluate", "--policy", str(policy), "--out", str(out), "--no-progress", "--algorithm", "my-ppo",
                 "--env-steps", "50000", "--training-seconds", "60"]) == 0
    board = _board(tmp_path)
    entry = lb.load_result(lb.submit(out, board))
    assert entry["provenance"] == "external" and entry["algorithm"] == "my-ppo"
    assert entry["training"]["env_steps"] == 50000 and "[external: training claims unverified]" in lb.show(board)


@pytest.fixture(scope="module")
def scripted():
    from ials_zoo import leaderboard as lb

    return lb.reference_result(ENV, "robot_20", "scripted", episodes=20)


def test_a_re_measure_is_bounded_before_it_starts(tmp_path, scripted, monkeypatch):
    """A variant entry of max_cycles 10**12 (valid): submit and verify refuse it at once with
    the estimate, instead of re-measuring 20 episodes of 10**12 steps."""
    import copy

    from ials_zoo import leaderboard as lb
    from ials_zoo.leaderboard import remeasure

    huge = copy.deepcopy(scripted)
    huge["evaluation"]["options"] = {"max_cycles": 10**12}
    huge["evaluation"]["protocol"] = "variant"
    path = tmp_path / "huge.json"
    path.write_text(json.dumps(huge))
    monkeypatch.setattr(remeasure, "evaluate", lambda *a, **k: (_ for _ in ()).throw(AssertionError("ran")))
    board = _board(tmp_path)
    for call in (lambda: lb.submit(path, board), lambda: lb.verify(path, directory=board)):
        with pytest.raises(lb.ResultError, match=r"would take about .* over the limit of 4\.0 h"):
            call()
    assert not list((board / "results").iterdir())


def test_impossible_metrics_are_refused(scripted):
    """A negative age at collection (recomputed so that every interval is consistent) is not a
    value the metric can take; neither are a negative per-seed bound or mean."""
    import copy

    from ials_zoo import leaderboard as lb

    bad = copy.deepcopy(scripted)
    for m in (bad["scores"][0]["metrics"]["age_at_collection"], bad["metrics"]["age_at_collection"]):
        m.pop("episodes"), m.pop("median")  # as an older result, which kept none: only the range can refuse it
        m.update(mean=-m["mean"] - 1, ci_low=-m["ci_high"] - 1, ci_high=-m["ci_low"] - 1)
    with pytest.raises(lb.ResultError, match="age_at_collection.* is not a value age_at_collection can take"):
        lb.validate_result(bad)
    lb.validate_result(scripted)


def test_a_metric_only_mismatch_says_which_metric_and_both_values(tmp_path, scripted):
    import copy

    from ials_zoo import leaderboard as lb

    forged = copy.deepcopy(scripted)
    seed_metric = forged["scores"][0]["metrics"]["items_per_robot"]
    for m in (seed_metric, forged["metrics"]["items_per_robot"]):
        m.pop("episodes"), m.pop("median")  # as an older result, which kept none: only the re-measure can tell
        m.update(mean=m["mean"] + 0.5, ci_low=m["ci_low"] + 0.5, ci_high=m["ci_high"] + 0.5)
    path = tmp_path / "f.json"
    path.write_text(json.dumps(forged))
    with pytest.raises(lb.ResultError) as err:
        lb.submit(path, _board(tmp_path))
    text = str(err.value)
    claimed, measured = seed_metric["mean"], scripted["scores"][0]["metrics"]["items_per_robot"]["mean"]
    assert "returns re-measure exactly, but not its metrics" in text
    assert f"items_per_robot claimed {claimed!r}, measured {measured!r}" in text


def test_a_metrics_episodes_must_give_its_mean_and_are_re_measured(tmp_path, scripted):
    """Each episode's value is kept: a mean its episodes do not give is refused on validate,
    and episodes forged together with their mean and interval are caught by the re-measure."""
    import copy

    from ials_zoo import leaderboard as lb
    from ials_zoo.evaluation import metric_summary

    forged = copy.deepcopy(scripted)
    forged["scores"][0]["metrics"]["items_per_robot"]["median"] += 0.5
    with pytest.raises(lb.ResultError, match="median: .* does not match its episodes"):
        lb.validate_result(forged)
    forged = copy.deepcopy(scripted)
    values = forged["scores"][0]["metrics"]["items_per_robot"]["episodes"]
    consistent = metric_summary([v + 0.5 for v in values])
    forged["scores"][0]["metrics"]["items_per_robot"] = consistent
    forged["metrics"]["items_per_robot"] = dict(consistent)
    lb.validate_result(forged)
    path = tmp_path / "f.json"
    path.write_text(json.dumps(forged))
    with pytest.raises(lb.ResultError, match="items_per_robot"):
        lb.submit(path, _board(tmp_path))


def test_show_escapes_control_characters_of_entry_strings(tmp_path, trained):
    """A valid entry whose algorithm holds a newline, a carriage return and an escape sequence
    cannot forge console rows."""
    from ials_zoo import leaderboard as lb

    board = _board(tmp_path)
    entry = json.loads((trained / "s0" / "result.json").read_text())
    entry["algorithm"] = "ippo\n[multi-agent] warehouse_v0 / forged\r\x1b[2K  best 999.00"
    (board / "results" / "e.json").write_text(json.dumps(entry))
    lb.load_result(board / "results" / "e.json")  # valid: show lists it
    shown = lb.show(board)
    assert "\x1b" not in shown and "\r" not in shown and "\n[multi-agent] warehouse_v0 / forged" not in shown
    assert "ippo\\n[multi-agent] warehouse_v0 / forged\\r\\x1b[2K" in shown


def _entry(algorithm, seed_means, trained=True):
    return {"env_id": ENV, "agents": ["robot_20"], "algorithm": algorithm, "evaluation": {"deterministic": False},
            "training": {"simulator": "gs"} if trained else None, "policy": {"kind": "model"},
            "scores": [{"seed": i, "mean": m} for i, m in enumerate(seed_means)]}


def test_compare_reports_the_probability_that_the_first_improves_on_the_second():
    from ials_zoo.leaderboard import compare_entries

    better, worse = _entry("better", [5.0, 6.0, 7.0]), _entry("worse", [1.0, 2.0, 3.0])
    assert "P(first > second) = 1.000" in compare_entries(better, worse)
    assert "P(first > second) = 0.000" in compare_entries(worse, better)


@pytest.mark.parametrize("first,match", [(_entry("one", [1.0]), "has 1 training seed"),
                                         (_entry("scripted", [1.0], trained=False), "reference entry")])
def test_compare_says_what_it_needs(first, match, capsys, tmp_path):
    from ials_zoo.leaderboard import compare_entries

    with pytest.raises(BadInput, match=match):
        compare_entries(first, _entry("two", [1.0, 2.0]))


def test_exit_status_convention_of_leaderboard_commands(tmp_path, capsys):
    """Bad input (a missing file, a bad argument) exits 2, as every command; a result that was
    read and rejected exits 1."""
    from ials_zoo.cli import main

    missing = str(tmp_path / "missing.json")
    board = _board(tmp_path)
    for action in (["submit", missing, "--dir", str(board)], ["validate", missing], ["verify", missing],
                   ["compare", missing, missing]):
        assert main(["leaderboard", *action]) == 2, action
    assert "does not exist" in capsys.readouterr().err
    (tmp_path / "bad.json").write_text("{}")
    assert main(["leaderboard", "submit", str(tmp_path / "bad.json"), "--dir", str(board)]) == 1


# -- 4. commands that refuse bad values up front ---------------------------------------------

@pytest.mark.parametrize("argv,match", [
    (["--policies", ""], "--policies names no policy"), (["--policies", ",,,"], "--policies names no policy"),
    (["--predictor", "on-policy-autoregressive", "--aip-influence-lags", "100000"], "influence"),
    (["--episodes", "1000000000000"], "--episodes"), (["--net", "cologne8"], "--net: warehouse_v0 takes no network"),
    (["--env", "sumo_net_v0", "--net", "cologne8", "--options", '{"net": "grid4x4"}'], "disagree"),
    (["--policies", "cycle:0"], "--policies: a cycle policy is cycle:H")])
def test_fidelity_refuses_bad_values_before_any_episode(argv, match, capsys, monkeypatch):
    from ials_zoo.cli import main
    from ials_zoo.influence import fidelity

    monkeypatch.setattr(fidelity, "run", lambda *a, **k: (_ for _ in ()).throw(AssertionError("ran")))
    assert main(["fidelity", "--env", "warehouse_v0", *argv]) == 2
    assert match in capsys.readouterr().err


def test_the_fidelity_report_uses_the_tolerance_it_was_given(monkeypatch):
    """Both sides of the edge: a difference of 0.99 x tolerance holds, 1.01 x does not (the
    interval alone excludes 0); and the command hands its --tolerance to every row."""
    import numpy as np

    from ials_zoo.cli import main
    from ials_zoo.influence import fidelity

    gs = 10.0 + np.random.default_rng(0).normal(0.0, 1e-3, 30)
    for tolerance in (0.1, 0.3):
        assert fidelity.compare(gs, gs - 0.99 * tolerance * 10.0, tolerance)["holds"]
        assert not fidelity.compare(gs, gs - 1.01 * tolerance * 10.0, tolerance)["holds"]
    seen, real = [], fidelity.compare

    def spy(gs, ials, tolerance):
        seen.append(tolerance)
        return real(gs, ials, tolerance)

    monkeypatch.setattr(fidelity, "compare", spy)
    assert main(["fidelity", "--env", "warehouse_v0", "--episodes", "2", "--policies", "constant", "--agents",
                 "robot_20", "--tolerance", "0.07"]) == 0
    assert seen and set(seen) == {0.07}


# -- 5. tests that catch what they claim to --------------------------------------------------

def test_the_iqm_interval_resamples_the_iqm_not_the_mean():
    """One seed of twenty scores 10**6: the IQM and its interval stay among the others; the
    mean's interval would reach past 10**4."""
    import numpy as np

    from ials_zoo.stats import iqm_interval

    x = np.concatenate([np.random.default_rng(0).normal(5.0, 1.0, 19), [1e6]])
    point, lo, hi = iqm_interval([x])
    assert 3.0 < lo <= point <= hi < 8.0


def test_marl_eval_export_carries_every_physical_metric():
    """Every metric of an exported seed is in its run's absolute_metrics, with its value."""
    from ials_zoo import leaderboard as lb
    from ials_zoo.leaderboard.export import task_label

    exported = lb.export_board("marl-eval")
    checked = 0
    for _, d in lb.load_entries()[0]:
        if d["policy"]["kind"] != "model" or d["evaluation"]["protocol"] != "official":
            continue  # the export holds the official trained entries only (a rule has no training seed)
        for s in d["scores"]:
            for name, value in (s.get("metrics") or {}).items():
                runs = [algos for task, algos in exported.get(d["env_id"], {}).items() if task == task_label(d)]
                found = [run["absolute_metrics"] for algos in runs for a in algos.values()
                         for key, run in a.items() if key == f"run_{s['seed']}" and name in run["absolute_metrics"]
                         and run["absolute_metrics"][name] == [float(value["mean"])]]
                checked += bool(runs)
                assert not runs or found, (d["env_id"], name)
    assert checked > 0


def test_an_autoregressive_aips_clock_starts_again_at_reset():
    """A second episode of one AIP with a clock gives the first one's probabilities again."""
    import numpy as np

    from ials_zoo.influence.networks import untrained_predictor

    region = get_region()
    for arch in ("mlp", "gru"):
        pred = untrained_predictor(region, arch, seed=0, hidden=8, autoregressive=True, influence_lags=1,
                                   clock_horizon=5)
        d = np.zeros((1, pred.dset_size), np.uint8)
        episodes = []
        for _ in range(2):
            pred.reset(1)
            episodes.append([pred.probs_padded(d).copy() for _ in range(4)])
        np.testing.assert_array_equal(np.array(episodes[0]), np.array(episodes[1]))


def get_region():
    from ials_zoo.core.domains import get_domain

    return get_domain(ENV).region_spec("robot_0", **OPTIONS)


def test_every_committed_board_file_is_valid():
    """The board's entries and archive all load (a schema change migrates them, or they would
    silently drop off the page)."""
    from ials_zoo import leaderboard as lb

    for subdir in ("results", "archive"):
        entries, problems = lb.load_entries(subdir=subdir)
        assert entries and not problems, problems[:3]


def test_a_discarded_new_run_leaves_what_was_in_its_folder(tmp_path):
    """A folder holding only hidden entries (a .git, a .env) is claimed for a new run; bad input
    found at the start removes what the run wrote and nothing else."""
    from ials_zoo.baselines import dials

    out = tmp_path / "d"
    (out / ".git").mkdir(parents=True)
    (out / ".git" / "HEAD").write_text("ref: refs/heads/main\n")
    (out / ".env").write_text("KEY=1\n")
    with pytest.raises(BadInput):
        dials.main(dials.Args(**dict(RUNS["dials"], env_options=json.dumps(dict(OPTIONS, itme_lifetime=3)),
                                     total_timesteps=256), out_dir=str(out)))
    assert sorted(p.name for p in out.iterdir()) == [".env", ".git"] and (out / ".git" / "HEAD").is_file()


def test_retraining_checks_the_file_it_compares_and_a_claimed_re_train_is_the_boards(tmp_path, trained):
    """The policy file at an entry's path must be the one it scored (its sha256) before a re-train
    compares against it; a result that arrives saying 're-trained' loses the claim at submit, and
    validate refuses one without a training command."""
    import copy

    from ials_zoo import leaderboard as lb
    from ials_zoo.baselines.retrain import retrain
    from ials_zoo.leaderboard.validate import ResultError

    board = _board(tmp_path)
    result = json.loads((trained / "s0" / "result.json").read_text())
    result["retrained"] = {"seeds": [0], "package_version": "x", "platform": "x", "date": "2026-01-01"}
    path = tmp_path / "claimed.json"
    result["scores"][0]["policy_file"] = str(trained / "s0" / "policy.safetensors")
    path.write_text(json.dumps(result))
    entry = lb.submit(path, board)
    assert "retrained" not in lb.load_result(entry)
    swapped = json.loads(entry.read_text())
    shutil.copyfile(trained / "s1" / "policy.safetensors", board / swapped["scores"][0]["policy_file"])
    with pytest.raises(ResultError, match="not the file the entry scored"):
        retrain(entry, directory=board)
    bare = copy.deepcopy(result)
    bare["training"].pop("reproduce")
    with pytest.raises(ResultError, match="records its training command"):
        lb.validate_result(bare)


def test_the_board_page_links_only_the_boards_own_policy_files(tmp_path, trained):
    from ials_zoo.leaderboard.site import render_site

    board = _board(tmp_path)
    entry = json.loads((trained / "s0" / "result.json").read_text())
    entry["scores"][0]["policy_file"] = "javascript:alert(1)"
    (board / "results" / "e.json").write_text(json.dumps(entry))
    page = render_site(board).read_text()
    assert 'href="javascript' not in page and "javascript:alert(1)" in page
    entry["learning_curves"] = [{"seed": 0, "points": []}]  # valid, and nothing to draw
    (board / "results" / "e.json").write_text(json.dumps(entry))
    assert "<svg" not in render_site(board).read_text()


def test_costs_and_numbers_that_do_not_fit_are_refused():
    """A traffic warm-up of 10**12 steps counts in a re-measure's estimate; 1e999 is no number."""
    from ials_zoo.evaluation import estimate_evaluation_seconds
    from ials_zoo.utils import loads_untrusted_json

    assert estimate_evaluation_seconds("traffic_grid_v0", 20, warmup_steps=10**12) > 10 * 4 * 3600
    with pytest.raises(BadInput, match="does not fit a float"):
        loads_untrusted_json('{"clock": 1e999}')


def test_a_dials_entry_re_trains_whatever_the_worker_count_and_headers_compare_types():
    """A DIALS run's header records its worker count and its AIP rounds' clocks: neither makes a
    re-train differ. And 1 is not 1.0 in a header."""
    import tempfile
    from pathlib import Path

    from ials_zoo.baselines import dials
    from ials_zoo.baselines.retrain import _first_difference, retrain

    out = Path(tempfile.mkdtemp(prefix="ials-zoo-dials-")) / "run"
    dials.main(dials.Args(**dict(RUNS["dials"], total_timesteps=256, eval_every=256, refresh="128",
                                 final_eval_episodes=20, workers=1), out_dir=str(out)))
    result = json.loads((out / "result.json").read_text())
    assert result["training"]["aip"]["refreshes"] == 2
    (report,) = retrain(out / "result.json")
    assert report["ok"], report
    assert _first_difference({"a": 1}, {"a": 1.0}) == "a (1 re-trained, 1.0 submitted)"
    from ials_zoo.baselines.retrain import _strip

    header = {"created": "x", "training": {"workers": 2, "backend": "process", "env_steps": 256,
                                           "aip": {"collection_seconds": 1.0, "last": {"created": "y", "refreshes": 2}}}}
    assert _strip(header) == {"training": {"env_steps": 256, "aip": {"last": {"refreshes": 2}}}}


def test_the_quiet_ctrl_c_is_the_commands_alone(tmp_path):
    """``python -m`` of another package that imports ials_zoo keeps Python's own Ctrl-C."""
    import signal
    import subprocess
    import sys

    pkg = tmp_path / "otherpkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("import ials_zoo\n")
    (pkg / "tool.py").write_text("import signal\nprint(signal.getsignal(signal.SIGINT) is signal.default_int_handler)\n")
    # started as a terminal starts a command: a suite run in the background (`cmd &` in a script)
    # ignores SIGINT, and a child would inherit that, not Python's handler
    proc = subprocess.run([sys.executable, "-m", "otherpkg.tool"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=120, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert proc.stdout.strip() == "True", proc.stderr[-2000:]
