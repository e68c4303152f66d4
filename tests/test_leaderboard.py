"""The leaderboard: schema + consistency validation, submit (atomic, no overwrite, no
duplicates), show, render, verify."""

import copy
import json
import os

import pytest

from ials_zoo import leaderboard as lb
from ials_zoo.evaluation import evaluate, mean_ci

ENV, AGENT = "warehouse_v0", "robot_20"


@pytest.fixture(scope="module")
def reference():
    """A real result: the scripted policy scored on 3 GS episodes."""
    return lb.reference_result(ENV, AGENT, "scripted", episodes=3, submitter="tests")


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


def test_reference_result_is_valid(reference):
    assert lb.validate_result(copy.deepcopy(reference)) == reference
    s = reference["scores"][0]
    assert (s["mean"], s["ci_low"], s["ci_high"]) == pytest.approx(mean_ci(s["returns"]))
    assert reference["domain"] == "warehouse" and reference["domain_version"] == 0
    assert s["policy_sha256"] is None


def test_submit_show_render(tmp_path, board, reference):
    dest = lb.submit(_write(tmp_path, reference), board)
    assert dest.parent == board / "results" and json.loads(dest.read_text()) == reference
    # a trained entry with a learning curve (numbers from a real evaluation of random play)
    ev = evaluate(ENV, AGENT, "random", episodes=3)
    trained = lb.make_result([ev], algorithm="ppo_single", training_seeds=[0], training={
        "simulator": "ials", "aip": None, "seeds": [0], "env_steps": 2000, "wall_clock_seconds": 30.0,
        "aip_seconds": 10.0, "hyperparameters": {}}, learning_curves=[{"seed": 0, "points": [
            {"env_steps": 1000, "wall_clock_seconds": 20.0, "mean": 1.0, "ci_low": 0.5, "ci_high": 1.5},
            {"env_steps": 2000, "wall_clock_seconds": 40.0, "mean": 1.2, "ci_low": 0.7, "ci_high": 1.7}]}])
    lb.submit(_write(tmp_path, trained, "t.json"), board)
    table = lb.show(board)
    assert "warehouse_v0 / robot_20" in table
    assert table.index("scripted") < table.index("ppo_single")  # sorted by score
    readme = lb.render(board)
    text = readme.read_text()
    assert "## warehouse_v0" in text and "### robot_20" in text and "plots/warehouse_v0__robot_20.png" in text
    png = board / "plots" / "warehouse_v0__robot_20.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _bad_variants(reference):
    def edit(fn):
        d = copy.deepcopy(reference)
        fn(d)
        return d

    def shift_mean(d):
        d["scores"][0]["mean"] += 0.5

    def shift_overall(d):
        d["score"]["mean"] += 0.5
        d["score"]["ci_high"] += 1.0

    def narrow_ci(d):
        d["scores"][0]["ci_low"] = d["scores"][0]["mean"] - 1e-3

    return [
        ("malformed json", "{not json", "(file)"),
        ("missing field", edit(lambda d: d["evaluation"].pop("episodes")), "evaluation.episodes"),
        ("wrong type", edit(lambda d: d["score"].__setitem__("mean", "high")), "score.mean"),
        ("bad sha", edit(lambda d: d["scores"][0].__setitem__("policy_sha256", "abc")), "scores.0.policy_sha256"),
        ("extra field", edit(lambda d: d.__setitem__("bonus", 1)), "bonus"),
        ("inconsistent mean", edit(shift_mean), "scores.0.mean"),
        ("inconsistent overall", edit(shift_overall), "score.mean"),
        ("inconsistent ci", edit(narrow_ci), "scores.0.ci_low"),
        ("returns vs episodes", edit(lambda d: d["scores"][0]["returns"].pop()), "scores.0.returns"),
        ("unknown domain", edit(lambda d: d.update(env_id="chess_v0", domain="chess")), "env_id"),
        ("domain/env mismatch", edit(lambda d: d.update(domain="traffic_grid")), "domain"),
        ("unknown version", edit(lambda d: d.update(env_id="warehouse_v7", domain_version=7)), "env_id"),
        ("unknown agent", edit(lambda d: d.update(agent="robot_99")), "agent"),
    ]


def test_submit_rejects_bad_files_and_leaves_the_board_untouched(tmp_path, board, reference):
    lb.submit(_write(tmp_path, reference), board)
    before = _snapshot(board)
    for name, data, field in _bad_variants(reference):
        path = _write(tmp_path, data, "bad.json")
        with pytest.raises(lb.ResultError) as info:
            lb.submit(path, board)
        assert field in str(info.value), (name, str(info.value))
        assert _snapshot(board) == before, name


def test_duplicates_are_refused(tmp_path, board, reference):
    lb.submit(_write(tmp_path, reference), board)
    before = _snapshot(board)
    again = dict(copy.deepcopy(reference), notes="same result, new notes", created="2030-01-01T00:00:00Z")
    with pytest.raises(lb.ResultError, match="duplicate"):
        lb.submit(_write(tmp_path, again, "again.json"), board)
    assert _snapshot(board) == before


def test_interrupted_submission_leaves_the_board_as_it_was(tmp_path, board, reference, monkeypatch):
    lb.submit(_write(tmp_path, reference), board)
    before = _snapshot(board)
    other = lb.reference_result(ENV, AGENT, "random", episodes=2)
    path = _write(tmp_path, other, "other.json")

    def crash(*args, **kwargs):
        raise OSError("disk full (simulated)")

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(OSError, match="simulated"):
        lb.submit(path, board)
    monkeypatch.undo()
    assert _snapshot(board) == before  # no entry, no temporary file
    lb.submit(path, board)  # and the same file goes in once the disk is back
    assert len(list((board / "results").glob("*.json"))) == 2


def test_cli_submit_names_the_field(tmp_path, board, reference, capsys):
    from ials_zoo.cli import main

    bad = copy.deepcopy(reference)
    bad["scores"][0]["mean"] += 1
    assert main(["leaderboard", "submit", str(_write(tmp_path, bad)), "--dir", str(board)]) == 1
    assert "scores.0.mean" in capsys.readouterr().err
    assert main(["leaderboard", "submit", str(_write(tmp_path, reference)), "--dir", str(board)]) == 0
    assert main(["leaderboard", "show", "--dir", str(board)]) == 0
    assert "scripted" in capsys.readouterr().out


def test_verify_rescoring(tmp_path, reference):
    ok = lb.verify(_write(tmp_path, reference))
    assert ok[0]["ok"] and ok[0]["exact"]
    # A consistent but false claim: returns doubled, statistics recomputed to match.
    forged = copy.deepcopy(reference)
    s = forged["scores"][0]
    s["returns"] = [2 * r for r in s["returns"]]
    s["mean"], s["ci_low"], s["ci_high"] = mean_ci(s["returns"])
    forged["score"] = lb.overall_score([s["mean"]], s)
    report = lb.verify(_write(tmp_path, forged, "forged.json"))
    assert not report[0]["ok"] and report[0]["measured"] == pytest.approx(reference["score"]["mean"])


def test_schema_file_is_draft_2020_12():
    import jsonschema

    schema = lb.load_schema()
    assert schema["$schema"].endswith("2020-12/schema")
    jsonschema.Draft202012Validator.check_schema(schema)


def test_committed_entries_are_valid_and_rendered():
    from pathlib import Path

    board = Path(__file__).resolve().parents[1] / "leaderboard"
    entries = lb.load_entries(board)
    assert entries, "the repository ships reference entries"
    readme = (board / "README.md").read_text()
    for path, data in entries:
        lb.validate_result(data)
        assert path.name == lb.entry_name(data)
        assert f"results/{path.name}" in readme, f"{path.name} missing from README (run render)"


def _trained(ev, seed, wall):
    return lb.make_result([ev], algorithm="ppo_single", training_seeds=[seed], training={
        "simulator": "gs", "aip": None, "seeds": [seed], "env_steps": 1000,
        "wall_clock_seconds": wall, "aip_seconds": 0.0, "hyperparameters": {}})


def test_merge_seeds_into_one_result(tmp_path):
    from ials_zoo.cli import main
    from ials_zoo.evaluation import CallablePolicy

    # two "seeds" of one experiment: two fixed-action policies scored on the same episodes
    a = _trained(evaluate(ENV, AGENT, CallablePolicy(lambda obs: 0, "up"), episodes=3), 0, 10.0)
    b = _trained(evaluate(ENV, AGENT, CallablePolicy(lambda obs: 3, "right"), episodes=3), 1, 20.0)
    merged = lb.merge_results([a, b])
    assert [s["seed"] for s in merged["scores"]] == [0, 1]
    assert merged["training"]["seeds"] == [0, 1] and merged["training"]["wall_clock_seconds"] == 15.0
    mean, lo, hi = mean_ci([a["score"]["mean"], b["score"]["mean"]])
    assert merged["score"] == {"mean": mean, "ci_low": lo, "ci_high": hi, "ci_over": "seeds"}
    with pytest.raises(lb.ResultError, match="seeds repeat"):
        lb.merge_results([a, a])
    c = copy.deepcopy(b)
    c["agent"] = "robot_21"
    with pytest.raises(lb.ResultError, match=r"results\[1\]\.agent"):
        lb.merge_results([a, c])
    out = tmp_path / "m.json"
    rc = main(["leaderboard", "merge", str(_write(tmp_path, a, "a.json")),
               str(_write(tmp_path, b, "b.json")), "--out", str(out)])
    assert rc == 0 and lb.load_result(out)["score"]["ci_over"] == "seeds"
