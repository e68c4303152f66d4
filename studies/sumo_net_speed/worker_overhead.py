"""Why the GS's default mode (a worker forked per episode) trails the in-process mode on small maps.

Usage: python studies/sumo_net_speed/worker_overhead.py [--net cologne8] [--repeats 5] [--out F.json]

Run it on a quiet machine: it measures, in one run,
1. the GS's share of raw SUMO in both modes (as ``ials-zoo bench``), and SUMO's own steps per second
   in each (raw SUMO time only);
2. a worker round trip (``ials_zoo.runtime.processes.Worker`` answering a trivial call), median and 10th/90th
   percentiles over 3,000 calls;
3. the minor page faults of one episode's steps, in this process and in a fresh worker;
4. the default mode again beside two busy loops at the lowest priority (nice 19), which keep the
   cores from idling: if idle cores waking up were the cost, the share would rise;
5. a round trip after the worker has computed for 0, 1, 5 and 20 ms, its two legs apart (the
   request reaching the worker, the answer reaching this process), through our worker and through
   a bare pipe between two forked processes;
6. one GS decision's crossing in the default mode, part by part: the request reaching the worker,
   the worker pickling the answer and writing it, the answer reaching the env (the clocks of both
   processes are the same ``perf_counter``), and the same pickle repeated in this process, warm.
Figures in docs/sumo_net.md ("Speed").
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import signal
import statistics
import struct
import subprocess
import sys
import time
from multiprocessing.connection import Connection

import numpy as np

from ials_zoo.runtime import processes
from ials_zoo.runtime.processes import Worker
from ials_zoo.sumo_net.benchmark import MODES, bench_map
from ials_zoo.sumo_net.core import NetCore
from ials_zoo.sumo_net.env import SumoNetEnv


def round_trip_us(calls: int = 3000) -> list[float]:
    worker = Worker(dict, (), name="round trip")
    try:
        lat = []
        for _ in range(calls):
            t = time.perf_counter()
            worker.call("get", "x")
            lat.append(time.perf_counter() - t)
    finally:
        worker.close()
    return [statistics.median(lat) * 1e6, float(np.percentile(lat, 10)) * 1e6, float(np.percentile(lat, 90)) * 1e6]


class _Spin:
    """A worker's object for item 5: computes for ``seconds``, returns when it started and ended."""

    def spin(self, seconds: float) -> tuple[float, float]:
        start = time.perf_counter()
        while time.perf_counter() - start < seconds:
            pass
        return start, time.perf_counter()


def _legs(call, work: float, calls: int = 200) -> list[float]:
    """Median µs of the request leg and the answer leg of ``call(work) -> (start, end)``."""
    request, answer = [], []
    for _ in range(calls):
        sent = time.perf_counter()
        start, end = call(work)
        answer.append(time.perf_counter() - end)
        request.append(start - sent)
    return [statistics.median(request) * 1e6, statistics.median(answer) * 1e6]


def _bare_pipe_child(requests: int, answers: int) -> None:
    while True:
        data = os.read(requests, 8)
        if not data:
            os._exit(0)
        os.write(answers, struct.pack("dd", *_Spin().spin(struct.unpack("d", data)[0])))


def legs_by_work(works=(0.0, 0.001, 0.005, 0.02)) -> dict:
    """Item 5: ``{"worker" | "bare pipe": {ms: [request µs, answer µs]}}``."""
    import sumo_net_worker_overhead as me  # the worker imports the class by this name, not __main__

    out = {"worker": {}, "bare pipe": {}}
    worker = Worker(me._Spin, (), name="spin")
    try:
        worker.started()
        for w in works:
            out["worker"][w * 1e3] = _legs(lambda s: worker.call("spin", s), w)
    finally:
        worker.close()
    req_r, req_w = os.pipe()
    ans_r, ans_w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child keeps only its own ends: its read sees EOF when this process dies
        os.close(req_w)
        os.close(ans_r)
        _bare_pipe_child(req_r, ans_w)

    def call(seconds):
        os.write(req_w, struct.pack("d", seconds))
        return struct.unpack("dd", os.read(ans_r, 16))

    try:
        for w in works:
            out["bare pipe"][w * 1e3] = _legs(call, w)
    finally:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    return out


class _TimedCore(NetCore):
    """Item 6's core: marks when each step starts and ends, and (in its worker only: it is built
    there) when the worker's loop receives, pickles and writes."""

    def __init__(self, **config):
        super().__init__(**config)
        self.marks = []
        dumps, send, recv = processes._dumps, Connection.send_bytes, Connection.recv_bytes

        def timed_dumps(obj):
            start = time.perf_counter()
            data = dumps(obj)
            self.marks.append(("pickle", start, time.perf_counter()))
            return data

        def timed_send(conn, *args, **kwargs):
            start = time.perf_counter()
            send(conn, *args, **kwargs)
            self.marks.append(("write", start, time.perf_counter()))

        def timed_recv(conn, *args, **kwargs):
            data = recv(conn, *args, **kwargs)
            self.marks.append(("received", time.perf_counter(), 0.0))
            return data

        processes._dumps, Connection.send_bytes, Connection.recv_bytes = timed_dumps, timed_send, timed_recv

    def step(self, actions):
        start = time.perf_counter()
        result = super().step(actions)
        self.marks.append(("step", start, time.perf_counter()))
        return result

    def take(self) -> list:
        marks, self.marks = self.marks, []
        return marks


class _TimedEnv(SumoNetEnv):
    CORE = "sumo_net_worker_overhead:_TimedCore"  # the worker imports this file by that name


def crossing_parts(net: str, episodes: int = 2) -> dict:
    """Item 6: median µs per decision of each part of the crossing, over ``episodes`` episodes."""
    from ials_zoo.sumo.lease import SimHandle

    calls, real = [], SimHandle.call

    def timed_call(handle, method, *args):
        start = time.perf_counter()
        result = real(handle, method, *args)
        if method == "step":
            calls.append((start, time.perf_counter()))
        return result

    env = _TimedEnv(net=net)
    rng = np.random.default_rng(0)  # every light at random, as the bench (a light held on green jams)
    parts = []
    SimHandle.call = timed_call
    try:
        for seed in range(episodes):
            env.reset(seed=seed)
            env._sim.call("take")
            calls.clear()
            while env.agents:
                env.step({a: int(rng.integers(env.action_space(a).n)) for a in env.agents})
            parts += _parts(env._sim.call("take"), calls)
    finally:
        SimHandle.call = real
        env.close()
    answer = ("ok", (env._measures, env._phases, env._time))  # the last decision's, as the worker sent it
    start = time.perf_counter()
    for _ in range(1000):
        processes._dumps(answer)
    warm = (time.perf_counter() - start) / 1000 * 1e6
    names = ["request reaches the worker", "worker: received to step", "worker: pickles the answer",
             "worker: writes it", "answer reaches the env", "the step itself"]
    return ({n: float(np.median([p[i] for p in parts]) * 1e6) for i, n in enumerate(names)}
            | {"the same pickle, warm, in this process": warm, "decisions": len(parts)})


def _parts(marks: list, calls: list) -> list[tuple]:
    """Per decision, from the worker's marks (received, step, pickle, write) and the env's calls."""
    out, i, k = [], 0, 0
    kinds = ["received", "step", "pickle", "write"]
    while i + 3 < len(marks) and k < len(calls):
        if [m[0] for m in marks[i:i + 4]] != kinds:
            i += 1
            continue
        received, step, pickled, written = marks[i:i + 4]
        sent, back = calls[k]
        out.append((received[1] - sent, step[1] - received[1], pickled[2] - pickled[1], written[2] - written[1],
                    back - written[2], step[2] - step[1]))
        i, k = i + 4, k + 1
    return out


def _minor_faults(pid: int | None) -> int:
    if pid is None:
        return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    with open(f"/proc/{pid}/stat") as f:
        return int(f.read().rsplit(")", 1)[1].split()[7])


def episode_faults(net: str, mode: str, seed: int = 0) -> int:
    """Minor page faults during one episode's steps (after a warm-up episode in the same env)."""
    env = SumoNetEnv(net=net, **MODES[mode])
    try:
        env.reset(seed=seed + 1)
        env.reset(seed=seed)
        pid = env._sim.worker_pid
        before = _minor_faults(pid)
        while env.agents:
            env.step({a: 0 for a in env.agents})
        return _minor_faults(pid) - before
    finally:
        env.close()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--net", default="cologne8")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    out = {"net": args.net}
    for mode in MODES:
        r = bench_map(args.net, repeats=args.repeats, mode=mode)
        out[mode] = r
        print(f"{mode}: GS / raw SUMO {r['gs_share_of_raw']}, SUMO steps/s {r['raw_sumo_steps_per_s']}", flush=True)
    out["round_trip_us"] = round_trip_us()
    print(f"worker round trip, µs: median, p10, p90 = {out['round_trip_us']}", flush=True)
    out["faults"] = {mode: episode_faults(args.net, mode) for mode in MODES}
    print(f"minor page faults of one episode's steps: {out['faults']}", flush=True)
    spinners = [subprocess.Popen(["nice", "-n", "19", sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        mode = next(iter(MODES))
        r = bench_map(args.net, repeats=args.repeats, mode=mode)
        out["default beside two nice-19 busy loops"] = r
        print(f"{mode} beside two nice-19 busy loops: GS / raw SUMO {r['gs_share_of_raw']}", flush=True)
    finally:
        for p in spinners:
            p.kill()
    out["legs_by_work_us"] = legs_by_work()
    print(f"round trip legs [request, answer] µs by the worker's ms of work: {out['legs_by_work_us']}", flush=True)
    out["crossing_us"] = crossing_parts(args.net)
    print(f"one decision's crossing, median µs: {out['crossing_us']}", flush=True)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
