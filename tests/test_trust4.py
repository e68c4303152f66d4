"""Trust, round four: wall-clocks a reader can compare, every cost bounded, pages and files that
show what they hold, processes that leave quietly, and tests for what let bugs live."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_trust3 import ENV, _board, scripted, trained  # noqa: F401  (module fixtures: two tiny IPPO runs, a rule)

from ials_zoo.errors import BadInput

# -- 4. pages and files that show what they hold ---------------------------------------------


def test_a_result_file_name_outside_the_boards_alphabet_is_skipped_by_name(tmp_path, trained):  # noqa: F811
    """A name holding markup would go raw into README.md's ``[json](...)`` link: the board names
    its files itself, so any other name is a problem named in the lists, never linked."""
    from ials_zoo import leaderboard as lb
    from ials_zoo.leaderboard.site import render_site

    board = _board(tmp_path)
    entry = (trained / "s0" / "result.json").read_text()
    (board / "results" / 'x"><img src=x onerror=alert(1)>.json').write_text(entry)
    (board / "results" / "fine_name-0.json").write_text(entry)
    entries, problems = lb.load_entries(board)
    assert [p.name for p, _ in entries] == ["fine_name-0.json"]
    assert len(problems) == 1 and "[A-Za-z0-9._-]" in problems[0][1]
    readme = lb.render(board).read_text()
    page = render_site(board).read_text()
    for text in (readme, page):
        assert "<img" not in text and "onerror=alert(1)>" not in text
    assert "fine_name-0.json" in readme


def test_control_and_direction_characters_are_escaped_on_the_page_and_in_the_readme(tmp_path, trained):  # noqa: F811
    """U+202E shows a name reversed, NUL/ESC/BEL/U+2028 break lines or terminals: the page and
    README write them as escapes, as ``show`` does."""
    from ials_zoo import leaderboard as lb
    from ials_zoo.leaderboard.site import render_site

    board = _board(tmp_path)
    entry = json.loads((trained / "s0" / "result.json").read_text())
    entry["algorithm"] = "ippo\u202eevil\x00\x1b[2K\u2028\x07"
    (board / "results" / "e.json").write_text(json.dumps(entry))
    lb.load_result(board / "results" / "e.json")  # a valid entry
    page = render_site(board).read_text()
    readme = lb.render(board).read_text()
    for text in (page, readme):
        assert not any(c in text for c in "\u202e\x00\x1b\u2028\x07"), repr(text[:200])
        assert "ippo\\u202eevil\\x00\\x1b" in text


def test_the_board_page_escapes_an_off_board_policy_path_and_an_algorithm_label(tmp_path, trained):  # noqa: F811
    from ials_zoo.leaderboard.site import render_site

    board = _board(tmp_path)
    entry = json.loads((trained / "s0" / "result.json").read_text())
    entry["scores"][0]["policy_file"] = '"><script>alert(1)</script>'
    entry["algorithm"] = "<img src=x onerror=alert(1)>"
    (board / "results" / "e.json").write_text(json.dumps(entry))
    page = render_site(board).read_text()
    assert "<script>alert" not in page and "<img src=x" not in page
    assert "&lt;img src=x onerror=alert(1)&gt;" in page and "&lt;script&gt;alert(1)&lt;/script&gt;" in page


# -- 5. processes: a resume of a run stopped before its first checkpoint -----------------------


def test_a_resume_before_the_first_checkpoint_keeps_the_state_and_names_overwrite(tmp_path):
    """Ctrl-C before the first checkpoint leaves ``interrupted``: a ``--resume`` says there is
    nothing to resume, names ``--overwrite``, and leaves the status as it was (not ``failed``)."""
    from ials_zoo.baselines.runs import INTERRUPTED, RunFolder, run_state

    settings = {"seed": 0, "lr": 1e-3}
    with pytest.raises(KeyboardInterrupt), RunFolder(tmp_path / "run", settings=settings).running():
        raise KeyboardInterrupt
    assert run_state(tmp_path / "run") == INTERRUPTED
    with pytest.raises(BadInput, match="was interrupted before its first checkpoint.*--overwrite"):
        RunFolder(tmp_path / "run", resume=True, settings=settings)
    assert run_state(tmp_path / "run") == INTERRUPTED
    RunFolder(tmp_path / "run", overwrite=True, settings=settings).release()  # and --overwrite starts it anew


# -- 6. tests for what let bugs live -----------------------------------------------------------


def test_a_checkpoint_of_the_same_run_id_with_other_settings_is_refused():
    """Only the settings digest differs: the run id alone would let it resume."""
    from ials_zoo.baselines.runs import check_binding

    binding = {"run_id": "r1", "settings_sha256": "b" * 64, "seed": 0}
    same = {"run": dict(binding)}
    check_binding("f", {"run_id": "r1"}, same, binding)  # this run's checkpoint resumes
    other = {"run": dict(binding, settings_sha256="a" * 64)}
    with pytest.raises(BadInput, match="written with other settings than this run's"):
        check_binding("f", {"run_id": "r1"}, other, binding)


@pytest.mark.parametrize("opening, closing", [("[", "]"), ('{"a":', "}")])
def test_the_json_depth_limit_accepts_its_depth_and_refuses_one_more(opening, closing):
    """At :data:`MAX_JSON_DEPTH` accepted, one deeper refused (not only 100,000 deep); brackets
    inside strings, escaped quotes among them, are not nesting."""
    from ials_zoo.utils import MAX_JSON_DEPTH, loads_untrusted_json

    def nested(depth):
        return opening * depth + "1" + closing * depth

    loads_untrusted_json(nested(MAX_JSON_DEPTH))
    with pytest.raises(BadInput, match=f"JSON nested {MAX_JSON_DEPTH + 1} deep"):
        loads_untrusted_json(nested(MAX_JSON_DEPTH + 1))
    # a string holding an escaped quote and brackets, at the limit: still accepted
    loads_untrusted_json(opening * MAX_JSON_DEPTH + '"\\"' + "[" * 10 + '"' + closing * MAX_JSON_DEPTH)


def test_a_metrics_upper_bound_is_checked(scripted):  # noqa: F811
    """No shipped domain bounds a metric from above: a domain that does refuses a mean past
    its bound and accepts one at it."""
    import dataclasses

    from ials_zoo.core.domains import get_domain
    from ials_zoo.leaderboard.validate import ResultError, _check_metrics

    mean = scripted["metrics"]["age_at_collection"]["mean"]
    highest = max([mean] + [s["metrics"]["age_at_collection"]["ci_high"] for s in scripted["scores"]])
    domain = get_domain(ENV)
    _check_metrics(scripted, dataclasses.replace(domain, metric_ranges={"age_at_collection": (0, highest)}))
    with pytest.raises(ResultError, match="is not a value age_at_collection can take"):
        _check_metrics(scripted, dataclasses.replace(domain, metric_ranges={"age_at_collection": (0, mean / 2)}))


def test_workers_orphaned_by_kill_9_leave_quietly():
    """The parent is killed while its worker computes an answer: the answer meets a broken pipe,
    and the worker leaves without a traceback on the terminal they share."""
    import subprocess
    import sys

    here = Path(__file__).resolve().parent
    code = (f"import os, signal, sys; sys.path.insert(0, {str(here)!r})\n"
            "from ials_zoo.runtime.processes import Worker\n"
            "from worker_fixtures import Slow\n"
            "w = Worker(Slow, (), preload=('worker_fixtures:linger_at_exit',)); w.started()\n"
            "w.send('nap'); os.kill(os.getpid(), signal.SIGKILL)\n")
    # stderr is read to its end: every process that holds it (the zygote, the worker) is gone
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == -9
    assert "Traceback" not in proc.stderr and "BrokenPipeError" not in proc.stderr, proc.stderr



# -- 3. networks as large as users bring ------------------------------------------------------


def test_a_load_that_holds_the_lock_is_given_its_budget_and_a_stall_is_still_named():
    """SUMO holds Python's lock while it loads a network, so its worker sends no heartbeat: with
    a load budget, a reset whose CPU time grows is waited for; one that computes nothing is
    named after ``unresponsive_after`` as before; without a budget the load is given up."""
    import time

    from ials_zoo.sumo.lease import SimHandle, WorkerUnresponsiveError

    core = "worker_fixtures:GilHoldingCore"
    sim = SimHandle(core, {}, "worker", unresponsive_after=0.5, load_seconds=20)
    try:
        assert sim.call("reset") == "loaded"  # about 1.5 s without a heartbeat
    finally:
        sim.close()
    sim = SimHandle(core, {"stall": True}, "worker", unresponsive_after=0.5, load_seconds=20)
    try:
        start = time.monotonic()
        with pytest.raises(WorkerUnresponsiveError, match="no heartbeat for 0.5 s"):
            sim.call("reset")  # silent and idle: named within seconds, whatever the budget
        assert time.monotonic() - start < 2.5
    finally:
        sim.close()
    sim = SimHandle(core, {}, "worker", unresponsive_after=0.5)
    try:
        with pytest.raises(WorkerUnresponsiveError):
            sim.call("reset")
    finally:
        sim.close()


def test_a_load_budget_grows_with_the_files():
    from ials_zoo.sumo.command import LOAD_SECONDS_BASE, load_budget
    from ials_zoo.sumo_net.scenario import make_scenario

    s = make_scenario(net="ingolstadt21")
    assert load_budget() == LOAD_SECONDS_BASE
    assert load_budget(s.net_file, *s.route_files) > load_budget(s.net_file) > LOAD_SECONDS_BASE


@pytest.mark.parametrize("backend", ["worker", "inprocess"])
def test_sumos_own_error_about_a_broken_network_reaches_the_user(tmp_path, backend):
    """libsumo says only ``Process Error``; SUMO's reason goes to file descriptor 2 (in a worker,
    a terminal). The error carries SUMO's lines."""
    import re

    from ials_zoo import sumo_net_v0
    from ials_zoo.sumo.lease import SimulationError
    from ials_zoo.sumo_net.scenario import make_scenario

    s = make_scenario(net="cologne1")
    text = Path(s.net_file).read_text()
    first_edge = re.search(r'<edge id="[^":][^"]*" from="[^"]*" to="[^"]*"', text).group(0)
    broken = tmp_path / "broken.net.xml"
    broken.write_text(text.replace(first_edge, re.sub(r' to="[^"]*"', "", first_edge), 1))
    env = sumo_net_v0.parallel_env(net_file=str(broken), route_files=list(s.route_files), backend=backend,
                                   fresh_process=False)
    try:
        with pytest.raises(SimulationError, match="Attribute 'to' is missing"):
            env.reset(seed=0)
    finally:
        env.close()


# -- 2. every cost of a re-train bounded before it starts ------------------------------------

W = "ials-zoo train {} --env-id warehouse_v0 --env-options '{{\"robots\": [2, 2]}}' "


@pytest.mark.parametrize("command,match", [
    (W.format("ippo") + "--hidden 100000,100000", "--hidden '100000,100000': at most"),
    (W.format("ippo") + "--frame-stack 1000000", "--frame-stack must be in \\[1, 64\\]"),
    (W.format("ppo_single") + "--batch-size 1", "--batch-size must be >= 2"),
    (W.format("ppo_single") + "--net-arch 100000,100000", "--net-arch '100000,100000': at most"),
    (W.format("ppo_shared") + "--batch-size 1", "--batch-size must be >= 2"),
    (W.format("ippo") + "--notes 'unbalanced", "cannot be read as a command line"),
    (W.format("ippo") + "--recurrent-hidden 100000", "--recurrent-hidden must be >= 0 and a GRU"),
])
def test_values_that_would_crash_a_re_train_are_refused_by_name(command, match):
    from ials_zoo.baselines.retrain import parse_command
    from ials_zoo.leaderboard.validate import ResultError

    with pytest.raises(ResultError, match=match):
        parse_command(command, 0)


def test_train_refuses_a_batch_of_one_by_name_and_leaves_no_run_folder(tmp_path, capsys):
    from ials_zoo.cli import main

    out = tmp_path / "run"
    argv = ["train", "ppo_single", "--env-id", "warehouse_v0", "--env-options", '{"robots": [2, 2]}',
            "--batch-size", "1", "--out-dir", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--batch-size must be >= 2" in err and "Traceback" not in err
    assert not out.exists()


def _entry_with_command(trained, command):  # noqa: F811
    data = json.loads((trained / "s0" / "result.json").read_text())
    data["training"]["reproduce"]["command"] = command
    return data


@pytest.mark.parametrize("change,match", [
    (lambda c: c.replace("train ippo", "train dials"), "trains baseline 'dials', but the entry is of 'ippo'"),
    (lambda c: c.replace("warehouse_v0", "traffic_grid_v0").replace(" --env-options '{\"robots\": [2, 2]}'", "")
     .replace(" --agents robot_0,robot_1,robot_2,robot_3", ""), "trains --env-id 'traffic_grid_v0'"),
    (lambda c: c.replace('[2, 2]', '[3, 3]'), "trains --env-options"),
    (lambda c: c + " --agents robot_0,robot_1", "trains --agents '2 agents'"),
])
def test_a_recorded_command_that_trains_something_else_is_refused_before_training(trained, change, match):  # noqa: F811
    """A re-train would run the command for minutes and only then find another baseline's,
    domain's or agents' policy: refused before it starts."""
    from ials_zoo.baselines.retrain import _check_matches_entry, parse_command
    from ials_zoo.leaderboard.validate import ResultError

    data = json.loads((trained / "s0" / "result.json").read_text())
    command = data["training"]["reproduce"]["command"]
    module, args = parse_command(command, 0)
    _check_matches_entry(data, "ippo", args)  # the entry's own command matches it
    changed = change(command)
    module, args = parse_command(changed, 0)
    with pytest.raises(ResultError, match=match):
        _check_matches_entry(data, module.__name__.rsplit(".", 1)[1], args)


@pytest.mark.parametrize("extra,named", [
    ("--n-epochs 1000000000", "--n-epochs"),
    ("--eval-every 1 --eval-episodes 1000000", "--eval-every/--eval-episodes"),
    ("--final-eval-episodes 1000000000", "--final-eval-episodes"),
])
def test_a_re_train_is_estimated_whole_and_refused_by_the_setting_that_costs(trained, extra, named, monkeypatch):  # noqa: F811
    from ials_zoo.baselines import ippo
    from ials_zoo.baselines.retrain import retrain
    from ials_zoo.leaderboard.validate import ResultError

    monkeypatch.setattr(ippo, "main", lambda *a: pytest.fail("it trained"))
    data = json.loads((trained / "s0" / "result.json").read_text())
    data["training"]["reproduce"]["command"] += " " + extra
    path = trained / "s0" / "edited.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ResultError, match=f"most of it from {named}.*over the limit of 4.0 h"):
        retrain(path)
    data["training"]["reproduce"]["command"] = data["training"]["reproduce"]["command"].replace(
        extra, '--env-options \'{"robots": [2, 2], "max_cycles": 1000000000000}\'')
    data["evaluation"]["options"]["max_cycles"] = 10**12  # an entry of such episodes (valid)
    path.write_text(json.dumps(data))
    with pytest.raises(ResultError, match="one episode of 1,000,000,000,000 steps"):
        retrain(path)


# -- 1. wall-clocks that can be compared --------------------------------------------------------


def test_the_reference_workload_leaves_the_runs_random_state_and_threads_alone():
    import torch

    from ials_zoo import reference_speed

    torch.manual_seed(7)
    expected = torch.rand(4)
    torch.manual_seed(7)
    threads = torch.get_num_threads()
    seconds = reference_speed.measure()
    assert 0 < seconds < 30
    assert torch.equal(torch.rand(4), expected) and torch.get_num_threads() == threads


def test_a_run_records_its_machines_speed_at_its_start_and_every_checkpoint(trained):  # noqa: F811
    from ials_zoo import reference_speed

    result = json.loads((trained / "s0" / "result.json").read_text())
    t, curve = result["training"], result["learning_curves"][0]["points"]
    ref = t["reference"]
    assert len(ref["seconds"]) == 1 + len(curve)  # the start, then a checkpoint at every evaluation
    total = t["wall_clock_seconds"] + t["aip_seconds"]
    assert ref["reference_seconds"] == pytest.approx(
        total * reference_speed.REFERENCE_WORKLOAD_SECONDS / sorted(ref["seconds"])[len(ref["seconds"]) // 2], rel=1e-3)
    assert ref["machine"] == reference_speed.machine() and ref["under_load"] == reference_speed.under_load(ref)


def test_a_resumed_run_keeps_the_timings_of_before_its_kill(tmp_path, monkeypatch):
    from test_trust3 import RUNS, _killed_after_first_checkpoint

    from ials_zoo import reference_speed
    from ials_zoo.baselines import ippo

    calls = iter([0.05, 0.06, 0.08, 0.09, 0.10, 0.11])
    monkeypatch.setattr(reference_speed, "measure", lambda *a: next(calls))
    out = tmp_path / "run"
    _killed_after_first_checkpoint(monkeypatch, ippo, out, 0)  # measured at the start and at step 0
    monkeypatch.setattr(reference_speed, "measure", lambda *a: next(calls))
    assert json.loads((out / "checkpoint.json").read_text())["reference"]["seconds"] == [0.05, 0.06]
    ippo.main(ippo.Args(**RUNS["ippo"], seed=0, out_dir=str(out), resume=True))
    ref = json.loads((out / "result.json").read_text())["training"]["reference"]
    assert ref["seconds"][:3] == [0.05, 0.06, 0.08] and len(ref["seconds"]) == 5  # + steps 256 and 512
    assert ref["under_load"]  # 0.05 to 0.10: more than 20%


def _with_reference(entry: dict, seconds: list, machine: str = "CPU A, 2 cores") -> dict:
    from ials_zoo import reference_speed

    t = entry["training"]
    record = {"workload": reference_speed.WORKLOAD, "machine": machine, "seconds": seconds}
    record["reference_seconds"] = reference_speed.reference_seconds(t["wall_clock_seconds"] + t["aip_seconds"], seconds)
    record["under_load"] = reference_speed.under_load(record)
    return dict(entry, training=dict(t, reference=record))


def test_the_board_shows_reference_seconds_and_marks_runs_timed_under_load(tmp_path, trained):  # noqa: F811
    from ials_zoo import leaderboard as lb
    from ials_zoo.leaderboard.site import render_site

    board = _board(tmp_path)
    entry = json.loads((trained / "s0" / "result.json").read_text())
    loaded = _with_reference(entry, [0.05, 0.05, 0.09])
    (board / "results" / "loaded.json").write_text(json.dumps(loaded))
    lb.load_result(board / "results" / "loaded.json")
    for text in (lb.show(board), lb.render(board).read_text(), render_site(board).read_text()):
        assert "on the reference machine" in text and "timed under load" in text
    quiet = _with_reference(entry, [0.05, 0.051])
    (board / "results" / "loaded.json").write_text(json.dumps(quiet))
    assert "timed under load" not in lb.show(board)


def test_a_reference_record_that_contradicts_its_timings_is_refused(trained):  # noqa: F811
    from ials_zoo import leaderboard as lb

    entry = _with_reference(json.loads((trained / "s0" / "result.json").read_text()), [0.05, 0.09])
    lb.validate_result(entry)
    entry["training"]["reference"]["under_load"] = False
    with pytest.raises(lb.ResultError, match="training.reference.under_load"):
        lb.validate_result(entry)
    entry["training"]["reference"].update(under_load=True, reference_seconds=1.0)
    with pytest.raises(lb.ResultError, match="training.reference.reference_seconds"):
        lb.validate_result(entry)


def test_compare_wall_clock_uses_reference_seconds_and_names_machines_and_load(trained):  # noqa: F811
    from ials_zoo.leaderboard import compare_wall_clock

    entry = json.loads((trained / "s0" / "result.json").read_text())
    t = entry["training"]
    t["wall_clock_seconds"], t["aip_seconds"] = 100.0, 0.0
    fast = _with_reference(entry, [0.05, 0.05], "CPU A, 2 cores")  # 100 s on a machine as fast as the reference
    t["wall_clock_seconds"] = 200.0
    slow = _with_reference(entry, [0.1, 0.1], "CPU B, 16 cores")  # 200 s on a machine half as fast
    text = compare_wall_clock(slow, fast)
    ratio = (200 / 0.1) / (100 / 0.05)
    assert f"first / second = {ratio:.2f} in reference seconds (2.00 in seconds)" in text
    assert "different machines" in text and "under load" not in text
    loaded = _with_reference(entry, [0.05, 0.1])
    assert "timed under load: first" in compare_wall_clock(loaded, fast)
    bare = dict(entry, training={k: v for k, v in t.items() if k != "reference"})
    assert "in seconds only" in compare_wall_clock(bare, fast)


def test_verify_retrain_reports_both_wall_clocks_in_reference_seconds(trained, capsys):  # noqa: F811
    from ials_zoo.cli import main

    assert main(["leaderboard", "verify", "--retrain", str(trained / "s0" / "result.json")]) == 0
    out = capsys.readouterr().out
    assert "re-made bit for bit" in out
    line = next(x for x in out.splitlines() if "wall-clock claimed" in x)
    assert line.count("on the reference machine") == 2 and "x in reference seconds" in line


# -- 6. Ctrl-C while starting: the imports finish, then the command ends ----------------------


def _fresh_process_sigint() -> None:
    """Ctrl-C as an ``ials-zoo`` process starts with it: Python's own handler (a test earlier
    in this long-lived pytest process may have left another disposition behind)."""
    import signal

    signal.signal(signal.SIGINT, signal.default_int_handler)


def test_ctrl_c_during_a_commands_imports_lets_them_finish_then_ends_with_130(monkeypatch, capsys):
    """A KeyboardInterrupt raised inside an import that runs compiled code aborts the process
    (exit -6, what made the start-up test flaky): the start-up only notes the Ctrl-C, lets the
    import finish and then ends the command, one line, exit 130."""
    import signal
    import sys

    from ials_zoo import cli

    _fresh_process_sigint()
    sys.modules.pop("interrupting_command", None)
    monkeypatch.setitem(cli.SUBCOMMANDS, "interrupting", ("interrupting_command", "x"))
    assert cli.main(["interrupting"]) == 130
    assert sys.modules["interrupting_command"].IMPORTED  # not cut short
    assert capsys.readouterr().err.strip() == "ials-zoo: interrupted"
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # Python's Ctrl-C is back


def test_dials_aip_rounds_count_in_a_re_trains_estimate(trained):  # noqa: F811
    """An AIP refresh every step of 10**8 collected steps would train for years: refused before."""
    from ials_zoo.baselines.retrain import _check_cost, parse_command
    from ials_zoo.leaderboard.validate import ResultError

    data = json.loads((trained / "s0" / "result.json").read_text())
    command = W.format("dials") + "--agents robot_0,robot_1,robot_2,robot_3 --total-timesteps 256 --refresh "
    _, args = parse_command(command + "once", 0)
    _check_cost(data, [(0, None, args, None)], 4 * 3600)  # one round of the domain's collection: fine
    _, args = parse_command(command + "1 --collect-steps 100000000", 0)
    with pytest.raises(ResultError, match="most of it from --refresh/--collect-steps \\(257 AIP rounds"):
        _check_cost(data, [(0, None, args, None)], 4 * 3600)


def test_a_submitted_headers_clock_that_is_no_number_never_crashes_a_finished_re_train():
    from ials_zoo.baselines.retrain import wall_clock_of, wall_clock_text

    bad = {"training": {"wall_clock_seconds": "soon", "aip_seconds": [1], "reference": {"reference_seconds": 3}}}
    claimed = wall_clock_of(bad)
    assert claimed == {"seconds": 0.0, "reference_seconds": 3.0, "under_load": False}
    good = {"training": {"wall_clock_seconds": 10.0, "aip_seconds": 2.0}}
    assert "claim has no reference" in wall_clock_text({"claimed": wall_clock_of(good), "retrained": claimed})


def test_reference_seconds_without_timings_or_unlike_the_headers_are_refused(trained):  # noqa: F811
    from ials_zoo import leaderboard as lb
    from ials_zoo.evaluation import load_model
    from ials_zoo.leaderboard.store import training_provenance

    entry = json.loads((trained / "s0" / "result.json").read_text())
    entry["training"]["reference"].update(seconds=[])
    with pytest.raises(lb.ResultError, match="training.reference.seconds"):
        lb.validate_result(entry)
    entry = json.loads((trained / "s0" / "result.json").read_text())
    net = load_model(trained / "s0" / "policy.safetensors").net
    training_provenance(entry, [net])  # the header's record is the result's
    entry["training"]["reference"]["reference_seconds"] /= 10  # faster than it ran
    with pytest.raises(lb.ResultError, match="training.reference"):
        training_provenance(entry, [net])


def test_seeds_timed_with_two_workload_versions_merge_without_a_reference():
    from ials_zoo import reference_speed

    one = {"workload": "ref-1", "machine": "A", "seconds": [0.05], "reference_seconds": 10.0, "under_load": False}
    assert reference_speed.merged([one, dict(one)])["reference_seconds"] == 10.0
    assert reference_speed.merged([one, dict(one, workload="ref-0")]) is None


def test_ctrl_c_during_start_up_then_help_still_says_interrupted(monkeypatch, capsys):
    import sys

    from ials_zoo import cli

    _fresh_process_sigint()
    sys.modules.pop("interrupting_command", None)
    monkeypatch.setitem(cli.SUBCOMMANDS, "interrupting", ("interrupting_command", "x"))
    assert cli.main(["interrupting", "--help"]) == 130
    assert capsys.readouterr().err.strip().endswith("ials-zoo: interrupted")
