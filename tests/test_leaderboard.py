"""The leaderboard: validation (schema, finite numbers, recomputed statistics, protocol), submit
(atomic, no overwrite, no duplicates, no code, policies copied in), show, render, exact verify."""

import copy
import json
import os

import numpy as np
import pytest

from ials_zoo import leaderboard as lb
from ials_zoo.cli import main
from ials_zoo.evaluation import CallablePolicy, evaluate, mean_ci
from ials_zoo.policy import PolicyNetwork, save_policy
from ials_zoo.stats import t_interval

ENV, AGENT = "warehouse_v0", "robot_20"


@pytest.fixture(scope="module")
def reference():
    """A real result: the scripted policy scored with the protocol (20 GS episodes)."""
    return lb.reference_result(ENV, AGENT, "scripted", submitter="tests")


@pytest.fixture
def board(tmp_path):
    d = tmp_path / "leaderboard"
    (d / "results").mkdir(parents=True)
    return d


def _write(tmp_path, data, name="r.json"):
    p = tmp_path / name
    p.write_text(data if isinstance(data, str) else json.dumps(data))
    return p


def _snapshot(directory):
    return {str(p.relative_to(directory)): p.read_bytes() for p in directory.rglob("*") if p.is_file()}


def _policy_file(tmp_path, seed=0, name="policy.safetensors"):
    rng = np.random.default_rng(seed)
    layers = [(rng.normal(size=(1, 37, 8)).astype(np.float32), np.zeros((1, 8), np.float32)),
              (rng.normal(size=(1, 8, 4)).astype(np.float32), np.zeros((1, 4), np.float32))]
    net = PolicyNetwork([AGENT], 37, 4, layers, metadata={"env_id": ENV})
    return save_policy(net, tmp_path / name)


def _model_result(tmp_path, seed=0, episodes=None, name="policy.safetensors"):
    path = _policy_file(tmp_path, seed, name)
    ev = evaluate(ENV, AGENT, str(path), **({} if episodes is None else {"episodes": episodes}))
    return lb.make_result([ev], algorithm="ppo_single", training_seeds=[seed], training={
        "simulator": "gs", "aip": None, "seeds": [seed], "env_steps": 1000,
        "wall_clock_seconds": 10.0 + seed, "aip_seconds": 0.0, "hyperparameters": {}})


def test_reference_result_is_valid(reference):
    assert lb.validate_result(copy.deepcopy(reference)) == reference
    s = reference["scores"][0]
    assert (s["mean"], s["ci_low"], s["ci_high"]) == pytest.approx(mean_ci(s["returns"]))
    assert reference["domain"] == "warehouse" and reference["domain_version"] == 0
    assert reference["evaluation"]["protocol"] == "official" and reference["track"] == "single-agent"
    assert s["policy_sha256"] is None


def test_submit_show_render(tmp_path, board, reference, capsys):
    dest = lb.submit(_write(tmp_path, reference), board)
    assert dest.parent == board / "results" and json.loads(dest.read_text()) == reference
    model = _model_result(tmp_path)
    model["learning_curves"] = [{"seed": 0, "points": [
        {"env_steps": 500, "wall_clock_seconds": 5.0, "mean": 1.0, "ci_low": 0.5, "ci_high": 1.5},
        {"env_steps": 1000, "wall_clock_seconds": 10.0, "mean": 1.2, "ci_low": 0.7, "ci_high": 1.7}]}]
    entry = json.loads(lb.submit(_write(tmp_path, model, "t.json"), board).read_text())
    # the policy file travels with the entry, under its sha256
    sha = entry["scores"][0]["policy_sha256"]
    assert entry["scores"][0]["policy_file"] == f"policies/{sha}.safetensors"
    assert (board / "policies" / f"{sha}.safetensors").is_file()
    table = lb.show(board)
    assert str(board.resolve()) in table and "warehouse_v0 / robot_20" in table
    assert table.index("scripted") < table.index("ppo_single")  # sorted by score
    readme = lb.render(board).read_text()
    assert "What an entry guarantees" in readme and (board / "plots").is_dir()
    # the board re-scores its entries from its own files
    assert lb.verify(board / "results" / lb.entry_name(entry), directory=board)[0]["ok"]


def test_submit_rejects_bad_files_and_leaves_the_board_untouched(tmp_path, board, reference):
    lb.submit(_write(tmp_path, reference), board)
    before = _snapshot(board)
    bad = copy.deepcopy(reference)
    bad["scores"][0]["returns"][0] += 1.0
    for data, match in [("{not json", "not valid JSON"), ([1, 2], "JSON object"), (bad, "scores.0.mean"),
                        ({**reference, "extra": 1}, "extra")]:
        with pytest.raises(lb.ResultError, match=match):
            lb.submit(_write(tmp_path, data, "bad.json"), board)
        assert _snapshot(board) == before


def test_claims_off_the_returns_are_refused(reference):
    """A mean +1.0 (or +1e-7) above the returns' mean is refused; so are non-finite numbers."""
    for delta in (1.0, 0.5, 1e-7):
        forged = copy.deepcopy(reference)
        forged["scores"][0]["mean"] += delta
        forged["score"]["mean"] += delta
        with pytest.raises(lb.ResultError, match="scores.0.mean"):
            lb.validate_result(forged)
    for field, value in (("returns", float("nan")), ("ci_high", float("inf"))):
        forged = copy.deepcopy(reference)
        if field == "returns":
            forged["scores"][0]["returns"][0] = value
        else:
            forged["scores"][0][field] = value
        with pytest.raises(lb.ResultError, match="not a finite number"):
            lb.validate_result(forged)


def test_non_finite_json_and_huge_files_are_refused(tmp_path, reference):
    text = json.dumps(reference).replace('"wall_clock_seconds"', '"x"', 0)
    text = text.replace(str(reference["score"]["mean"]), "NaN", 1)
    with pytest.raises(lb.ResultError, match="NaN"):
        lb.load_result(_write(tmp_path, text))
    big = tmp_path / "big.json"
    big.write_text(" " * (lb.MAX_RESULT_BYTES + 1) + "{}")
    with pytest.raises(lb.ResultError, match="at most"):
        lb.load_result(big)


def test_protocol_is_enforced(tmp_path, board):
    """Other seeds or options: a variant, listed apart; claiming 'official' for them is refused."""
    ev = evaluate(ENV, AGENT, "random", seeds=list(range(10)))
    variant = lb.make_result([ev], algorithm="random")
    assert variant["evaluation"]["protocol"] == "variant"
    forged = copy.deepcopy(variant)
    forged["evaluation"]["protocol"] = "official"
    with pytest.raises(lb.ResultError, match="evaluation.protocol"):
        lb.validate_result(forged)
    opts = lb.make_result([evaluate(ENV, AGENT, "random", item_probability=0.2)], algorithm="random")
    assert opts["evaluation"]["protocol"] == "variant"
    dup = copy.deepcopy(variant)
    dup["evaluation"]["seeds"] = [5] * 10
    with pytest.raises(lb.ResultError, match="seeds repeat"):
        lb.validate_result(dup)
    neg = copy.deepcopy(variant)
    neg["evaluation"]["seeds"][0] = -1
    with pytest.raises(lb.ResultError, match="evaluation.seeds"):
        lb.validate_result(neg)
    lb.submit(_write(tmp_path, variant), board)
    assert "[variants] warehouse_v0" in lb.show(board)


def test_duplicates_are_judged_by_what_was_evaluated(tmp_path, board, reference):
    lb.submit(_write(tmp_path, reference), board)
    again = copy.deepcopy(reference)
    again["notes"], again["created"], again["submitter"] = "again", "2030-01-01T00:00:00Z", "someone"
    with pytest.raises(lb.ResultError, match="duplicate"):
        lb.submit(_write(tmp_path, again, "again.json"), board)
    model = _model_result(tmp_path)
    lb.submit(_write(tmp_path, model, "m.json"), board)
    retrained = copy.deepcopy(model)  # same policy file, other training record
    retrained["training"]["wall_clock_seconds"] = 1.0
    with pytest.raises(lb.ResultError, match="duplicate"):
        lb.submit(_write(tmp_path, retrained, "m2.json"), board)


def test_code_and_unverifiable_policies_are_refused(tmp_path, board):
    ev = evaluate(ENV, AGENT, CallablePolicy(lambda obs: 0, "os:system"), episodes=20)
    code = lb.make_result([ev], algorithm="callable")
    with pytest.raises(lb.ResultError, match="callable policy is code"):
        lb.submit(_write(tmp_path, code), board)
    with pytest.raises(lb.ResultError, match="never imports"):
        lb.verify(_write(tmp_path, code))
    model = _model_result(tmp_path)
    model["scores"][0]["policy_file"] = "missing.safetensors"
    with pytest.raises(lb.ResultError, match="not found"):
        lb.submit(_write(tmp_path, model, "m.json"), board)
    other = _model_result(tmp_path, seed=1, name="other.safetensors")
    other["scores"][0]["policy_file"] = "policy.safetensors"  # another file than the one scored
    with pytest.raises(lb.ResultError, match="sha256"):
        lb.submit(_write(tmp_path, other, "o.json"), board)


def test_bad_files_on_the_board_are_named_and_the_rest_works(tmp_path, board, reference, capsys):
    lb.submit(_write(tmp_path, reference), board)
    (board / "results" / "corrupt.json").write_text("{oops")
    (board / "results" / "foreign.json").write_text(json.dumps({"hello": "world"}))
    (board / "results" / ".~x.json.abcd1234.tmp").write_text("half")  # a killed write
    table = lb.show(board)
    assert "skipped corrupt.json" in table and "skipped foreign.json" in table and "scripted" in table
    model = _model_result(tmp_path)
    lb.submit(_write(tmp_path, model, "m.json"), board)  # submitting still works
    readme = lb.render(board).read_text()  # named and skipped: one bad file never hides the rest
    assert "corrupt.json" in readme and "foreign.json" in readme and "scripted" in readme


def test_board_location_is_explicit(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("IALS_ZOO_LEADERBOARD", raising=False)
    assert main(["leaderboard", "show"]) == 2
    assert "no leaderboard at" in capsys.readouterr().err


def test_verify_is_exact(tmp_path, reference):
    ok = lb.verify(_write(tmp_path, reference))
    assert ok[0]["ok"] and not ok[0]["differences"]
    # A consistent but false claim: returns shifted, statistics recomputed to match.
    forged = copy.deepcopy(reference)
    s = forged["scores"][0]
    s["returns"] = [r + 1e-6 for r in s["returns"]]
    s["mean"], s["ci_low"], s["ci_high"] = mean_ci(s["returns"])
    forged["score"] = lb.overall_score([s])
    report = lb.verify(_write(tmp_path, forged, "forged.json"))
    assert not report[0]["ok"] and len(report[0]["differences"]) == 20
    assert main(["leaderboard", "verify", str(_write(tmp_path, forged, "f.json"))]) == 1


def test_schema_file_is_draft_2020_12():
    import jsonschema

    schema = lb.load_schema()
    assert schema["$schema"].endswith("2020-12/schema")
    jsonschema.Draft202012Validator.check_schema(schema)


def test_committed_entries_are_valid_verifiable_and_rendered():
    from pathlib import Path

    board = Path(__file__).resolve().parents[1] / "leaderboard"
    entries, problems = lb.load_entries(board)
    assert not problems, problems
    assert entries, "the repository ships reference entries"
    readme = (board / "README.md").read_text()
    for path, data in entries:
        assert path.name == lb.entry_name(data)
        assert f"results/{path.name}" in readme, f"{path.name} missing from README (run render)"
        for s in data["scores"]:  # every scored policy is on the board, with its sha256
            if s["policy_file"]:
                from ials_zoo.evaluation import sha256_file

                assert sha256_file(board / s["policy_file"]) == s["policy_sha256"]


def _trained(ev, seed, wall):
    return lb.make_result([ev], algorithm="ppo_single", training_seeds=[seed], training={
        "simulator": "gs", "aip": None, "seeds": [seed], "env_steps": 1000,
        "wall_clock_seconds": wall, "aip_seconds": 0.0, "hyperparameters": {}})


def test_merge_seeds_into_one_result(tmp_path):
    a = _trained(evaluate(ENV, AGENT, CallablePolicy(lambda obs: 0, "up"), episodes=3), 0, 10.0)
    b = _trained(evaluate(ENV, AGENT, CallablePolicy(lambda obs: 3, "right"), episodes=3), 1, 20.0)
    merged = lb.merge_results([a, b])
    assert [s["seed"] for s in merged["scores"]] == [0, 1]
    assert merged["training"]["seeds"] == [0, 1] and merged["training"]["wall_clock_seconds"] == 15.0
    mean, lo, hi = t_interval([a["score"]["mean"], b["score"]["mean"]])
    assert merged["score"] == {"mean": mean, "ci_low": lo, "ci_high": hi, "ci_over": "seeds"}
    with pytest.raises(lb.ResultError, match="seeds repeat"):
        lb.merge_results([a, a])
    c = copy.deepcopy(b)
    c["agent"] = c["agents"][0] = "robot_21"
    with pytest.raises(lb.ResultError, match=r"results\[1\]\.agent"):
        lb.merge_results([a, c])
    out = tmp_path / "m.json"
    rc = main(["leaderboard", "merge", str(_write(tmp_path, a, "a.json")),
               str(_write(tmp_path, b, "b.json")), "--out", str(out)])
    assert rc == 0 and lb.load_result(out)["score"]["ci_over"] == "seeds"


def test_merging_results_in_their_run_folders_keeps_their_policies(tmp_path):
    paths = []
    for seed in (0, 1):
        run = tmp_path / f"run_s{seed}"
        run.mkdir()
        r = _model_result(run, seed, episodes=2)
        r["scores"][0]["policy_file"] = "policy.safetensors"  # as a training run writes it, beside its result
        paths.append(str(_write(run, r, "result.json")))
    out = tmp_path / "merged" / "m.json"
    out.parent.mkdir()
    assert main(["leaderboard", "merge", *paths, "--out", str(out)]) == 0
    merged = json.loads(out.read_text())
    assert [s["policy_file"] for s in merged["scores"]] == [f"../run_s{k}/policy.safetensors" for k in (0, 1)]
    assert lb.load_result(out)["scores"][1]["seed"] == 1  # every policy found beside the merged file


def test_interrupted_submission_leaves_the_board_as_it_was(tmp_path, board, reference, monkeypatch):
    before = _snapshot(board)

    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(KeyboardInterrupt):
        lb.submit(_write(tmp_path, reference), board)
    monkeypatch.undo()
    assert _snapshot(board) == before
