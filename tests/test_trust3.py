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
             total_timesteps=512, eval_every=256)
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
