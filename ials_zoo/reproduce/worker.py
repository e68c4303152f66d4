"""Worker process of ``ials-zoo reproduce``: ``python -m ials_zoo.reproduce.worker JOB.json``.

Runs one job (see :mod:`ials_zoo.reproduce.plan`) in this fresh process, with torch on one
thread, and exits 0 when the job's marker file was written.
"""

from __future__ import annotations

import json
import sys
import time
from importlib import import_module
from pathlib import Path

import torch

from ials_zoo.baselines.ppo_single import Args
from ials_zoo.baselines.ppo_single import main as train_ppo_single
from ials_zoo.baselines.runs import run_state
from ials_zoo.errors import BadInput
from ials_zoo.reproduce import experiments as X
from ials_zoo.reproduce.plan import Job
from ials_zoo.runtime.processes import die_with_parent


def run_job(job) -> None:
    """Run ``job`` (a :class:`~ials_zoo.reproduce.plan.Job`) in this process."""
    torch.set_num_threads(1)
    p = dict(job.params)
    if job.kind == "aip":
        X.train_aip(p["env_id"], p["agent"], job.dir, steps=p["steps"], epochs=p.get("epochs"),
                    seed=p.get("seed", 0), options=p.get("options"), arch=p.get("arch"),
                    workers=p.get("workers", 1))
    elif job.kind == "ppo":
        # a job killed earlier continues from its last checkpoint; one killed before its first
        # checkpoint starts again
        state = run_state(p["out_dir"])
        if state is not None:
            resumable = (Path(p["out_dir"]) / "checkpoint.pt").is_file() and state != "finished"
            p["resume" if resumable else "overwrite"] = True
        train_ppo_single(Args(**p))
    elif job.kind == "multiagent":
        _run_multiagent(p)
    elif job.kind == "joint-reference":
        X.joint_reference(p, job.dir)
    elif job.kind == "lifetimes":
        X.run_lifetimes(p, job.dir)
    elif job.kind == "dset":
        X.dset_ablation(p, job.dir)
    else:
        raise BadInput(f"unknown job kind {job.kind!r}")


def _run_multiagent(params: dict) -> None:
    """A GS-IPPO or DIALS run (:mod:`ials_zoo.baselines.ippo` / ``.dials``); a run killed
    earlier continues from its last checkpoint, one killed before it starts again."""

    p = dict(params)
    module = import_module(f"ials_zoo.baselines.{p.pop('algorithm')}")
    state = run_state(p["out_dir"])
    if state is not None:
        resumable = (Path(p["out_dir"]) / "checkpoint.pt").is_file() and state != "finished"
        p["resume" if resumable else "overwrite"] = True
    module.main(module.Args(**p))


def main(argv=None) -> int:
    die_with_parent()  # the study's runner started this process: it ends with it
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m ials_zoo.reproduce.worker JOB.json", file=sys.stderr)
        return 2
    job = Job.from_dict(json.loads(Path(argv[0]).read_text()))
    t0 = time.perf_counter()
    print(f"job {job.id} ({job.kind}) started", flush=True)
    run_job(job)
    print(f"job {job.id} finished in {time.perf_counter() - t0:.1f} s", flush=True)
    return 0 if job.done else 1


if __name__ == "__main__":
    sys.exit(main())
