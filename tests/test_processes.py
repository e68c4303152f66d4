"""Processes: every child dies with its parent however the parent dies; Ctrl-C ends a run
promptly; a stopped SUMO worker is detected in seconds."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ials_zoo.sumo.lease import WorkerDiedError, WorkerUnresponsiveError
from ials_zoo.traffic.env import TrafficGridEnv


def _children(pid: int) -> set[int]:
    """Every live descendant of ``pid`` (from /proc)."""
    parents = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            parents[int(entry.name)] = int(stat.rsplit(")", 1)[1].split()[1])
    out, todo = set(), [pid]
    while todo:
        p = todo.pop()
        for c, pp in parents.items():
            if pp == p and c not in out:
                out.add(c)
                todo.append(c)
    return out


def _alive(pids) -> set[int]:
    alive = set()
    for p in pids:
        try:
            state = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            alive.add(p)
    return alive


def _default_sigint():
    # as a terminal starts a command: a suite run in the background (`cmd &` in a script)
    # inherits an ignored SIGINT, which the command would inherit in turn
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start(args, tmp_path):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "ials_zoo.cli", *args], cwd=tmp_path, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True,
                            preexec_fn=_default_sigint)


def _wait_for_children(proc, n, timeout=90):
    deadline = time.time() + timeout
    seen = set()
    while time.time() < deadline:
        seen |= _children(proc.pid)
        if len(_alive(seen)) >= n:
            time.sleep(1.0)  # let the evaluator pool start too
            return seen | _children(proc.pid)
        if proc.poll() is not None:
            pytest.fail(f"the command ended early: {proc.stderr.read().decode()[-2000:]}")
        time.sleep(0.2)
    pytest.fail(f"only {len(_alive(seen))} children appeared")


def _gone_within(pids, seconds=10):
    deadline = time.time() + seconds
    while _alive(pids) and time.time() < deadline:
        time.sleep(0.2)
    return not _alive(pids)


TRAIN = ["train", "ppo_single", "--env", "traffic_grid_v0", "--simulator", "gs", "--n-envs", "2",
         "--total-timesteps", "200000", "--n-steps", "64", "--batch-size", "64", "--net-arch", "8",
         "--eval-every", "128", "--eval-episodes", "50", "--no-progress", "--out-dir", "run"]


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_training_children_die_with_the_parent(tmp_path, sig):
    proc = _start(TRAIN, tmp_path)
    try:
        kids = _wait_for_children(proc, 3)  # two GS workers and the evaluation worker
        os.kill(proc.pid, sig)
        proc.wait(timeout=30)
        assert _gone_within(kids), f"left behind: {_alive(kids)}"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    if sig == signal.SIGTERM:
        from ials_zoo.baselines.runs import run_state

        assert run_state(tmp_path / "run") == "interrupted"
    else:
        from ials_zoo.baselines.runs import run_state

        assert run_state(tmp_path / "run") == "killed"


def test_ctrl_c_ends_a_traffic_run_promptly(tmp_path):
    proc = _start(TRAIN, tmp_path)
    try:
        kids = _wait_for_children(proc, 3)
        t0 = time.time()
        os.kill(proc.pid, signal.SIGINT)
        rc = proc.wait(timeout=30)
        assert rc == 130 and time.time() - t0 < 15
        assert _gone_within(kids), f"left behind: {_alive(kids)}"
        assert "interrupted" in proc.stderr.read().decode()
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


def test_collection_workers_die_with_the_parent(tmp_path):
    proc = _start(["collect", "--env", "traffic_grid_v0", "--agent", "tls_12", "--steps", "100000",
                   "--workers", "2", "--no-progress", "--out", "d.npz"], tmp_path)
    try:
        kids = _wait_for_children(proc, 2)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        assert _gone_within(kids), f"left behind: {_alive(kids)}"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert not list(tmp_path.glob("*.npz"))


def test_a_stopped_sumo_worker_is_detected_in_seconds():
    env = TrafficGridEnv(grid=(2, 2), backend="worker", max_cycles=50)
    try:
        env.reset(seed=0)
        pid = env._sim.worker_pid
        os.kill(pid, signal.SIGSTOP)
        t0 = time.time()
        with pytest.raises(WorkerUnresponsiveError, match="heartbeat"):
            env.step({a: 0 for a in env.agents})
        assert time.time() - t0 < 10
        assert _gone_within({pid}, 5)  # it was killed
        env.reset(seed=0)  # a new worker
        env.step({a: 0 for a in env.agents})
        os.kill(env._sim.worker_pid, signal.SIGKILL)
        with pytest.raises(WorkerDiedError):
            env.step({a: 0 for a in env.agents})
    finally:
        env.close()


def test_sumo_workers_die_with_their_parent(tmp_path):
    code = ("from ials_zoo.traffic.env import TrafficGridEnv; import time; "
            "e = TrafficGridEnv(grid=(2, 2), backend='worker'); e.reset(seed=0); print(e._sim.worker_pid, flush=True); "
            "time.sleep(60)")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    worker = int(proc.stdout.readline())
    family = _children(proc.pid)  # the zygote the worker was forked from, and the worker
    assert worker in family and len(family) >= 2
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert _gone_within(family, 5)


def test_forked_workers_are_the_zygotes_leave_no_zombies_and_die_with_it():
    import random

    from ials_zoo.runtime.processes import SERVE_ENTRY, Worker
    from ials_zoo.runtime.zygote import zygote_for

    preload = ("random", "no_such_module_here")  # a preload that fails costs nothing but its speed
    workers = [Worker(random.Random, (seed,), name="forked worker", preload=preload) for seed in (1, 2, 3)]
    zygote = zygote_for(preload, SERVE_ENTRY)
    try:
        for w in workers:
            w.started()
        assert [w.call("random") for w in workers] == [random.Random(s).random() for s in (1, 2, 3)]
        assert {w.pid for w in workers} == _children(zygote.process.pid)  # forked, not fresh interpreters
        workers[0].close()
        os.kill(workers[1].pid, signal.SIGKILL)
        with pytest.raises(Exception, match="died"):
            workers[1].call("random")
        assert workers[1].process.returncode == -signal.SIGKILL  # the zygote kept its exit code
        assert _children(zygote.process.pid) == {workers[2].pid}  # the others reaped: no zombies
        os.kill(zygote.process.pid, signal.SIGKILL)  # the zygote's death takes its workers with it
        assert _gone_within({workers[2].pid}, 5)
        again = Worker(random.Random, (4,), preload=preload)  # and the next worker gets a new zygote
        again.started()
        assert again.call("random") == random.Random(4).random()
        assert zygote_for(preload, SERVE_ENTRY) is not zygote
        again.close()
    finally:
        for w in workers:
            w.close(kill=True)


def test_a_worker_killed_between_calls_is_named_dead_whichever_end_notices():
    """Killed and gone before the next call, the worker's pipe refuses the call itself (EPIPE):
    that too says it died, as when the death shows while waiting for an answer."""
    import random

    from ials_zoo.runtime.processes import Worker

    worker = Worker(random.Random, (1,), name="forked worker", preload=("random",))
    try:
        worker.started()
        os.kill(worker.pid, signal.SIGKILL)
        assert _gone_within({worker.pid}, 10)
        with pytest.raises(Exception, match="died"):
            worker.call("random")
    finally:
        worker.close(kill=True)


def test_an_answer_cut_short_is_never_taken_for_the_next_one(monkeypatch):
    import random

    from ials_zoo.runtime import zygote as zygotes
    from ials_zoo.runtime.processes import SERVE_ENTRY, Worker

    preload = ("random", "json")
    Worker(random.Random, (0,), preload=preload).close()  # the zygote has answered once
    zygote = zygotes.zygote_for(preload, SERVE_ENTRY)
    real = zygotes.Zygote._receive

    def cut_short(self, number):
        raise KeyboardInterrupt  # Ctrl-C after the fork request went out, before its answer came

    monkeypatch.setattr(zygotes.Zygote, "_receive", cut_short)
    with pytest.raises(KeyboardInterrupt):
        Worker(random.Random, (1,), preload=preload)
    monkeypatch.setattr(zygotes.Zygote, "_receive", real)
    import importlib

    w = Worker(importlib.import_module, ("os",), preload=preload)  # a worker that is the os module
    w.started()
    assert w.call("getpid") == w.pid  # its own pid, not the answer to the cut-short request
    assert zygotes.zygote_for(preload, SERVE_ENTRY) is zygote
    w.close()
    deadline = time.time() + 5  # the cut-short fork found its pipes closed, exited and was reaped
    while _children(zygote.process.pid) and time.time() < deadline:
        time.sleep(0.2)
    assert not _children(zygote.process.pid)


def test_a_fork_of_the_parent_leaves_the_parents_workers_alone():
    import random

    from ials_zoo.runtime.processes import Worker

    w = Worker(random.Random, (0,), preload=("random",))
    w.started()
    pid = os.fork()
    if pid == 0:  # the fork closes its copy of the handle: it must not kill the parent's worker
        try:
            w.close(kill=True)
        finally:
            os._exit(0)
    os.waitpid(pid, 0)
    assert w.call("random") == random.Random(0).random()
    w.close()


def test_seeds_are_checked_and_never_alias():
    import ials_zoo
    from ials_zoo.warehouse.env import parallel_env

    with pytest.raises(ValueError, match="seed must be an int"):
        parallel_env().reset(seed=-1)
    env = TrafficGridEnv(grid=(2, 2))
    try:
        a = env.reset(seed=5)[0]
        with pytest.raises(ValueError, match="seed must be an int in \\[0, 2147483646\\]"):
            env.reset(seed=5 + 2**31 - 1)
        np.testing.assert_array_equal(env.reset(seed=5)[0]["tls_0"], a["tls_0"])
    finally:
        env.close()
    # Gymnasium's semantics: the constructor's seed stands for the first reset only
    ials = ials_zoo.make_ials("warehouse_v0", "robot_20", predictor="uniform", seed=7)
    ials.reset(seed=100)
    second = [ials.step(t % 4)[0] for t in range(30)]
    ials.reset()
    third = [ials.step(t % 4)[0] for t in range(30)]
    fresh = ials_zoo.make_ials("warehouse_v0", "robot_20", predictor="uniform", seed=7)
    fresh.reset()
    seven = [fresh.step(t % 4)[0] for t in range(30)]
    assert not all(np.array_equal(x, y) for x, y in zip(third, seven))
    assert not all(np.array_equal(x, y) for x, y in zip(third, second))


def test_training_in_this_process_keeps_ctrl_c():
    """Only worker processes hand Ctrl-C to their parent; the training process keeps it."""
    from ials_zoo.single_agent import make_gs_vec_env

    before = signal.getsignal(signal.SIGINT)  # Python's handler, or SIG_IGN when run in the background
    venv = make_gs_vec_env("warehouse_v0", "robot_20", n_envs=2)  # DummyVecEnv: in this process
    venv.close()
    assert signal.getsignal(signal.SIGINT) is before


# -- processes.Worker: the one worker protocol -------------------------------------------------

def test_a_worker_answers_calls_and_names_its_errors():
    import queue
    import random

    from ials_zoo.runtime.processes import Worker, WorkerError, call_all, start_all

    workers = [Worker(random.Random, (seed,), name=f"test worker {seed}") for seed in (1, 2)]
    start_all(workers)
    try:
        assert call_all(workers, "random") == [random.Random(1).random(), random.Random(2).random()]
        with pytest.raises(WorkerError, match=r"test worker 1 \(pid \d+\) failed: IndexError(?s:.*)Traceback"):
            workers[0].call("choice", [])
        assert workers[1].call("randint", 3, 3) == 3  # the other one is untouched
    finally:
        for w in workers:
            w.close()
    assert not _alive({w.pid for w in workers})
    blocked = Worker(queue.Queue, name="blocked worker", detail="a queue")
    blocked.started()
    t0 = time.monotonic()
    with pytest.raises(WorkerError, match=r"blocked worker \(pid \d+, a queue\) did not answer within 1 s"):
        blocked.call("get", timeout=1.0)  # blocks forever in the worker, which still beats
    assert time.monotonic() - t0 < 5 and _gone_within({blocked.pid}, 5)
    with pytest.raises(WorkerError, match="failed: TypeError"):
        Worker(random.Random, ("a", "b", "c")).started()  # the constructor's error


@pytest.mark.parametrize("preload", [None, ("random",)], ids=["fresh", "forked"])
@pytest.mark.parametrize("how", ["kill", "stop"])
def test_a_dead_or_stopped_worker_is_named_within_seconds(how, preload):
    import random

    from ials_zoo.runtime.processes import Worker, WorkerError

    worker = Worker(random.Random, (0,), name="test worker", unresponsive_after=3.0, preload=preload)
    worker.started()
    os.kill(worker.pid, signal.SIGKILL if how == "kill" else signal.SIGSTOP)
    t0 = time.monotonic()
    with pytest.raises(WorkerError, match="died" if how == "kill" else "is stopped"):
        worker.call("random")
    assert time.monotonic() - t0 < 10 and _gone_within({worker.pid}, 5)


def test_sending_to_a_stopped_worker_never_blocks_and_bad_input_inside_stays_bad_input():
    import random

    from ials_zoo.errors import BadInput
    from ials_zoo.runtime.processes import Worker, WorkerError

    worker = Worker(random.Random, (0,), name="test worker")
    worker.started()
    os.kill(worker.pid, signal.SIGSTOP)
    t0 = time.monotonic()
    with pytest.raises(WorkerError, match="is stopped"):
        worker.send("seed", "x" * 5_000_000)  # far more than a pipe holds
    assert time.monotonic() - t0 < 10 and _gone_within({worker.pid}, 5)
    import functools

    from ials_zoo.warehouse.env import WarehouseEnv

    bad = Worker(functools.partial(WarehouseEnv, colour="red"), name="env worker")
    try:
        with pytest.raises(BadInput, match="unknown option\\(s\\) \\['colour'\\]"):
            bad.started()  # bad input found inside a worker is still bad input (one line, exit 2)
        with pytest.raises(WorkerError, match="never built"):
            bad.call("reset")
    finally:
        bad.close()
