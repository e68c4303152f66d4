"""A run stopped after a checkpoint and resumed ends bitwise equal to the run that was never
stopped: the same weights, learning curve, score and training log, for IPPO, for DIALS on
every backend and with either learner, and for the SB3 baselines (ppo_single on the GS and on
an IALS, ppo_shared).

The stop is a crash at the GS evaluation after a checkpoint, so the run trained past its last
checkpoint (an AIP refresh included) in the middle of the GS and IALS episodes (the budgets
are not multiples of an episode); the kill -9 variant is in ``test_dials.py``. Runs use the
2x2 warehouse, tiny networks and budgets."""

import json

import numpy as np
import pytest
from same_run import assert_same_run

ENV = "warehouse_v0"
OPTIONS = {"robots": [2, 2]}
AGENTS = ["robot_0", "robot_1", "robot_2", "robot_3"]
COMMON = dict(env_id=ENV, agents=",".join(AGENTS), env_options=json.dumps(OPTIONS), n_envs=2,
              samples_per_update=128, batch_size=64, n_epochs=2, hidden="16", eval_episodes=1,
              final_eval_episodes=2, progress=False, checkpoint_every=0)
# DIALS: AIPs retrained at 0, 384 and 768 steps per agent, checkpoints every 256: the crash at
# 512 resumes from 256, replays an IALS episode 28 steps in and redoes the refresh at 384;
# 1024 = 10.24 GS episodes.
DIALS = dict(COMMON, total_timesteps=1024, eval_every=256, refresh="384", collect_steps=200, aip_epochs=1)
IPPO = dict(COMMON, total_timesteps=768, eval_every=256)


class Crash(RuntimeError):
    pass


def _crash_after_checkpoints(monkeypatch, n: int):
    """The next run crashes at its ``n + 1``-th GS evaluation, before that checkpoint: after
    its ``n``-th checkpoint it trained on (and logged) more, which the resume must redo."""
    from ials_zoo.baselines import driver

    real, seen = driver._curve_point, []

    def point(*args, **kwargs):
        if len(seen) == n:
            raise Crash(f"stopped after checkpoint {n}")
        seen.append(real(*args, **kwargs))
        return seen[-1]

    monkeypatch.setattr(driver, "_curve_point", point)


def _crash_at_checkpoint(monkeypatch, n: int):
    """The next run crashes at its ``n + 1``-th checkpoint (evaluations' included); returns the
    real ``driver._checkpoint`` and the list of steps checkpointed before the crash."""
    from ials_zoo.baselines import driver

    real, calls = driver._checkpoint, []

    def checkpoint(*args, **kw):
        if len(calls) == n:
            raise Crash(f"stopped after checkpoint {n}")
        calls.append(args[2])
        return real(*args, **kw)

    monkeypatch.setattr(driver, "_checkpoint", checkpoint)
    return real, calls


def _progress_rows(folder):
    """progress.csv without its wall-clock column (the one thing a resumed run may differ in)."""
    import csv

    with open(folder / "progress.csv", newline="") as f:
        return [row[:1] + row[2:] for row in csv.reader(f)]


def _agent_returns_match_the_mean(folder) -> list:
    """agent_returns.csv's rows, each checked against progress.csv: its agents' mean is the
    row's mean episode return."""
    import csv

    with open(folder / "agent_returns.csv", newline="") as f:
        per_agent = list(csv.DictReader(f))
    with open(folder / "progress.csv", newline="") as f:
        progress = list(csv.DictReader(f))
    assert [r["steps_per_agent"] for r in per_agent] == [r["steps_per_agent"] for r in progress if r["mean_episode_return"]]
    means = {r["steps_per_agent"]: float(r["mean_episode_return"]) for r in progress if r["mean_episode_return"]}
    for row in per_agent:
        values = [float(v) for k, v in row.items() if k != "steps_per_agent" and v]
        assert np.mean(values) == pytest.approx(means[row["steps_per_agent"]], rel=1e-9)
    assert per_agent  # episodes ended
    return per_agent


def _stopped_and_resumed(monkeypatch, module, out, kwargs, checkpoints=2):
    _crash_after_checkpoints(monkeypatch, checkpoints)
    with pytest.raises(Crash):
        module.main(module.Args(**kwargs, out_dir=str(out)))
    monkeypatch.undo()
    assert json.loads((out / "status.json").read_text())["state"] == "failed"
    assert not (out / "result.json").exists()
    return module.main(module.Args(**kwargs, out_dir=str(out), resume=True)), out


@pytest.mark.parametrize("workers,backend", [(0, "process"), (2, "process"), (2, "ray")])
def test_a_resumed_dials_run_ends_bitwise_as_the_uninterrupted_one(tmp_path, monkeypatch, workers, backend):
    if backend == "ray":
        pytest.importorskip("ray")
    from ials_zoo.baselines import dials

    kwargs = dict(DIALS, workers=workers, backend=backend)
    whole = dials.main(dials.Args(**kwargs, out_dir=str(tmp_path / "whole"))), tmp_path / "whole"
    resumed = _stopped_and_resumed(monkeypatch, dials, tmp_path / "resumed", kwargs)
    assert_same_run(whole, resumed)
    assert _progress_rows(whole[1]) == _progress_rows(resumed[1])  # no stretch logged twice
    assert resumed[0]["training"]["aip"]["refreshes"] == whole[0]["training"]["aip"]["refreshes"] == 3


def test_a_resumed_ippo_run_ends_bitwise_as_the_uninterrupted_one(tmp_path, monkeypatch):
    from ials_zoo.baselines import ippo

    whole = ippo.main(ippo.Args(**IPPO, out_dir=str(tmp_path / "whole"))), tmp_path / "whole"
    resumed = _stopped_and_resumed(monkeypatch, ippo, tmp_path / "resumed", IPPO)
    assert_same_run(whole, resumed)
    assert _progress_rows(whole[1]) == _progress_rows(resumed[1])


IDQN = dict(env_id=ENV, agents=",".join(AGENTS), env_options=json.dumps(OPTIONS), n_envs=2, total_timesteps=768,
            eval_every=256, eval_episodes=1, final_eval_episodes=2, progress=False, checkpoint_every=0, hidden="16",
            buffer_size=300, target_update=50)


@pytest.mark.parametrize("kwargs", [IDQN, dict(IDQN, env_id="sumo_net_v0", agents="all", n_envs=1,
                                               env_options=json.dumps({"net": "cologne3", "max_cycles": 30}),
                                               total_timesteps=96, eval_every=32, final_eval_episodes=1)],
                         ids=["warehouse", "cologne3"])
def test_a_resumed_idqn_run_ends_bitwise_as_the_uninterrupted_one(tmp_path, monkeypatch, kwargs):
    """The replay buffers, target networks, optimiser and counters come back whole, and the
    episode in flight is replayed; on cologne3 the lights have actions of their own counts."""
    from ials_zoo.baselines import idqn

    whole = idqn.main(idqn.Args(**kwargs, out_dir=str(tmp_path / "whole"))), tmp_path / "whole"
    resumed = _stopped_and_resumed(monkeypatch, idqn, tmp_path / "resumed", kwargs)
    assert_same_run(whole, resumed)
    rows = _progress_rows(whole[1])
    assert rows == _progress_rows(resumed[1])
    assert rows[0] == ["steps_per_agent", "mean_episode_return", "loss", "q_mean", "epsilon", "updates"]
    assert all(row[2] and row[4] for row in rows[1:])  # every stretch says its loss and epsilon


def test_resumed_mplight_and_shared_ppo_runs_end_bitwise_as_the_uninterrupted_ones(tmp_path, monkeypatch):
    """The shared learners come back whole too: MPLight's pooled replay on cologne3's lights of
    their own action counts, and the shared actor-critic on the warehouse."""
    from ials_zoo.baselines import mplight, shared_ppo

    for module, kwargs in ((mplight, dict(IDQN, env_id="sumo_net_v0", agents="all", n_envs=1, total_timesteps=96,
                                          env_options=json.dumps({"net": "cologne3", "max_cycles": 30}),
                                          eval_every=32, final_eval_episodes=1)),
                           (shared_ppo, IPPO)):
        folder = tmp_path / module.__name__.rsplit(".", 1)[-1]
        whole = module.main(module.Args(**kwargs, out_dir=str(folder / "whole"))), folder / "whole"
        resumed = _stopped_and_resumed(monkeypatch, module, folder / "resumed", kwargs)
        assert_same_run(whole, resumed)
        assert _progress_rows(whole[1]) == _progress_rows(resumed[1])
        assert _agent_returns_match_the_mean(whole[1]) == _agent_returns_match_the_mean(resumed[1])


@pytest.mark.parametrize("module_name", ["ippo", "dials"])
def test_a_resumed_traffic_run_ends_bitwise_as_the_uninterrupted_one(tmp_path, monkeypatch, module_name):
    """SUMO in the GS copies (IPPO) and in the local simulators (DIALS), two lights."""
    import importlib

    module = importlib.import_module(f"ials_zoo.baselines.{module_name}")
    kwargs = dict(env_id="traffic_grid_v0", agents="tls_12,tls_13", n_envs=2, samples_per_update=128, batch_size=64,
                  n_epochs=2, hidden="16", eval_episodes=1, final_eval_episodes=1, progress=False,
                  total_timesteps=1024, eval_every=256)
    if module_name == "dials":
        kwargs.update(refresh="384", collect_steps=300, aip_epochs=1, workers=2)
    whole = module.main(module.Args(**kwargs, out_dir=str(tmp_path / "whole"))), tmp_path / "whole"
    assert_same_run(whole, _stopped_and_resumed(monkeypatch, module, tmp_path / "resumed", kwargs))


SINGLE = dict(env_id=ENV, env_options=json.dumps(OPTIONS), agent="robot_0", total_timesteps=1024, n_envs=2, n_steps=64,
              batch_size=64, n_epochs=2, net_arch="16", eval_every=256, eval_episodes=1, final_eval_episodes=2,
              progress=False)


@pytest.mark.parametrize("simulator,extra", [("gs", {}), ("untrained-ials", {"anneal_lr": True}),
                                             ("fixed:0.2", {"frame_stack": 2})])
def test_a_resumed_ppo_single_run_ends_bitwise_as_the_uninterrupted_one(tmp_path, monkeypatch, simulator, extra):
    """SB3's PPO on the GS and on IALSs (the AIP's random stream), with the reward scale, a
    learning rate that decays, a frame stack: the crash at 512 steps resumes from 256, in the
    middle of 100-step episodes."""
    from ials_zoo.baselines import ppo_single

    kwargs = dict(SINGLE, simulator=simulator, **extra)
    whole = ppo_single.main(ppo_single.Args(**kwargs, out_dir=str(tmp_path / "whole"))), tmp_path / "whole"
    resumed = _stopped_and_resumed(monkeypatch, ppo_single, tmp_path / "resumed", kwargs)
    assert_same_run(whole, resumed)
    assert _progress_rows(whole[1]) == _progress_rows(resumed[1])
    for name in ("result.json", "result_deterministic.json"):
        a, b = (json.loads((f / name).read_text()) for f in (whole[1], resumed[1]))
        assert a["scores"][0]["returns"] == b["scores"][0]["returns"]


def test_a_resumed_traffic_ppo_single_run_ends_bitwise_as_the_uninterrupted_one(tmp_path, monkeypatch):
    """SUMO GS copies in worker processes, restarted at each checkpoint from their seeds: the
    crash at 900 steps resumes from 300, half-way through 300-step episodes."""
    from ials_zoo.baselines import ppo_single

    kwargs = dict(env_id="traffic_grid_v0", agent="tls_12", simulator="gs", total_timesteps=1200, n_envs=2,
                  n_steps=150, batch_size=150, n_epochs=2, net_arch="16", eval_every=300, eval_episodes=1,
                  final_eval_episodes=1, progress=False)
    whole = ppo_single.main(ppo_single.Args(**kwargs, out_dir=str(tmp_path / "whole"))), tmp_path / "whole"
    assert_same_run(whole, _stopped_and_resumed(monkeypatch, ppo_single, tmp_path / "resumed", kwargs))


def test_a_resume_from_a_checkpoint_between_evaluations_is_bitwise_too(tmp_path, monkeypatch):
    """``--eval-every 0``: checkpoints alone between the start and the end (every 256 steps
    here); the crash comes at the third, after training past the second."""
    from ials_zoo.baselines import driver, ppo_single

    monkeypatch.setattr(ppo_single, "CHECKPOINT_EVERY", 256)
    kwargs = dict(SINGLE, simulator="gs", eval_every=0)
    whole = ppo_single.main(ppo_single.Args(**kwargs, out_dir=str(tmp_path / "whole"))), tmp_path / "whole"
    assert [p["env_steps"] for p in whole[0]["learning_curves"][0]["points"]] == [0, 1024]
    real, calls = _crash_at_checkpoint(monkeypatch, 2)
    with pytest.raises(Crash):
        ppo_single.main(ppo_single.Args(**kwargs, out_dir=str(tmp_path / "resumed")))
    assert calls == [0, 256]
    monkeypatch.setattr(driver, "_checkpoint", real)
    resumed = ppo_single.main(ppo_single.Args(**kwargs, out_dir=str(tmp_path / "resumed"), resume=True))
    assert_same_run(whole, (resumed, tmp_path / "resumed"))
    assert _progress_rows(whole[1]) == _progress_rows(tmp_path / "resumed")


def test_a_multi_agent_run_checkpoints_between_evaluations_by_default_and_resumes_from_there_bitwise(
        tmp_path, monkeypatch):
    """IPPO's default cadence: a checkpoint every quarter of ``--eval-every`` too (here every
    128-step update between the evaluations at 0, 512 and 768). The crash comes at 512, after
    the checkpoint at 384 between evaluations, and the resume starts there. The reference run
    checkpoints only at its evaluations (``--checkpoint-every 0``): where checkpoints fall does
    not change the run."""
    from ials_zoo.baselines import driver, ippo

    kwargs = dict(IPPO, eval_every=512, checkpoint_every=None)
    whole = ippo.main(ippo.Args(**dict(kwargs, checkpoint_every=0), out_dir=str(tmp_path / "whole")))
    assert "--checkpoint-every" not in whole["training"]["reproduce"]["command"]  # watching, not computing
    real, calls = _crash_at_checkpoint(monkeypatch, 4)
    with pytest.raises(Crash):
        ippo.main(ippo.Args(**kwargs, out_dir=str(tmp_path / "resumed")))
    assert calls == [0, 128, 256, 384]
    monkeypatch.setattr(driver, "_checkpoint", real)
    resumed = ippo.main(ippo.Args(**kwargs, out_dir=str(tmp_path / "resumed"), resume=True))
    assert_same_run((whole, tmp_path / "whole"), (resumed, tmp_path / "resumed"))


def test_a_resumed_ppo_shared_run_ends_bitwise_as_the_uninterrupted_one(tmp_path, monkeypatch):
    from ials_zoo.baselines import ppo_shared

    kwargs = dict(env_id=ENV, env_options=json.dumps(OPTIONS), learners="robot_0,robot_1", total_timesteps=1024,
                  n_steps=64, batch_size=64, n_epochs=2, net_arch="16", eval_every=256, eval_episodes=1,
                  final_eval_episodes=2, progress=False)
    whole = ppo_shared.main(ppo_shared.Args(**kwargs, out_dir=str(tmp_path / "whole"))), tmp_path / "whole"
    resumed = _stopped_and_resumed(monkeypatch, ppo_shared, tmp_path / "resumed", kwargs)
    assert_same_run((whole[0][0], whole[1]), (resumed[0][0], resumed[1]))
    assert _progress_rows(whole[1]) == _progress_rows(resumed[1])


@pytest.mark.parametrize("workers", [0, 2])
def test_a_resumed_dials_run_with_sb3_learners_ends_bitwise_as_the_uninterrupted_one(tmp_path, monkeypatch, workers):
    from ials_zoo.baselines import dials

    kwargs = dict(DIALS, workers=workers, backend="process", learner="sb3")
    whole = dials.main(dials.Args(**kwargs, out_dir=str(tmp_path / "whole"))), tmp_path / "whole"
    resumed = _stopped_and_resumed(monkeypatch, dials, tmp_path / "resumed", kwargs)
    assert_same_run(whole, resumed)
    assert _progress_rows(whole[1]) == _progress_rows(resumed[1])


def test_an_sb3_resume_without_its_weights_or_its_random_streams_would_be_caught(tmp_path, monkeypatch):
    """The ppo_single check is not blind: a resume that loads no weights, or that leaves the
    random streams as the fresh model set them, ends elsewhere."""
    from ials_zoo.baselines import ppo_single
    from ials_zoo.learners import sb3_state

    kwargs = dict(SINGLE, simulator="gs")
    whole = ppo_single.main(ppo_single.Args(**kwargs, out_dir=str(tmp_path / "whole"))), tmp_path / "whole"
    real_load = sb3_state.load_model_state
    mutants = {"weights": ("load_model_state", lambda model, state: real_load(model, dict(
                   state, policy=model.policy.state_dict()))),
               "streams": ("set_random_streams", lambda state: None)}
    for name, (attribute, mutant) in mutants.items():
        out = tmp_path / name
        _crash_after_checkpoints(monkeypatch, 2)
        with pytest.raises(Crash):
            ppo_single.main(ppo_single.Args(**kwargs, out_dir=str(out)))
        monkeypatch.undo()
        monkeypatch.setattr(sb3_state, attribute, mutant)
        resumed = ppo_single.main(ppo_single.Args(**kwargs, out_dir=str(out), resume=True)), out
        monkeypatch.undo()
        with pytest.raises(AssertionError):
            assert_same_run(whole, resumed)


def test_a_resume_that_started_from_the_initial_weights_would_be_caught(tmp_path, monkeypatch):
    """The check above is not blind: a resume that loads no weights (the mutant of
    ``BatchedPPO.load_state_dict`` that copies nothing) ends elsewhere."""
    from ials_zoo.baselines import ippo
    from ials_zoo.learners.batched_ppo import BatchedPPO

    whole = ippo.main(ippo.Args(**IPPO, out_dir=str(tmp_path / "whole"))), tmp_path / "whole"
    real = BatchedPPO.load_state_dict

    def forgetful(self, state):
        real(self, dict(state, params={k: v.detach().clone() for k, v in self.params.items()}))

    _crash_after_checkpoints(monkeypatch, 2)
    with pytest.raises(Crash):
        ippo.main(ippo.Args(**IPPO, out_dir=str(tmp_path / "resumed")))
    monkeypatch.undo()
    monkeypatch.setattr(BatchedPPO, "load_state_dict", forgetful)
    resumed = ippo.main(ippo.Args(**IPPO, out_dir=str(tmp_path / "resumed"), resume=True)), tmp_path / "resumed"
    with pytest.raises(AssertionError):
        assert_same_run(whole, resumed)


def test_the_trainer_replays_a_saved_episode_to_the_same_state():
    """``RolloutTrainer.state``/``restore`` on the GS copies: the restored trainer's stacked
    observations and its next rollout are those of the trainer that saved."""
    from ials_zoo.learners.batched_ppo import BatchedPPO, PPOConfig
    from ials_zoo.learners.gs_vec import GSVecEnv
    from ials_zoo.learners.rollout import RolloutTrainer

    cfg = PPOConfig(n_steps=30, n_envs=2, hidden=(16,), batch_size=60, n_epochs=1)

    def trainer():
        learner = BatchedPPO(AGENTS, 37 * 2, 4, cfg, seed=3)
        return RolloutTrainer(learner, GSVecEnv(ENV, AGENTS, 2, seed=0, **OPTIONS), frame_stack=2, seed=3), learner

    first, learner = trainer()
    first.collect_and_update()  # 30 steps into a 100-step episode
    saved, weights = first.state(), learner.state_dict()
    assert saved["episode"] == 0 and len(saved["actions"]) == 30
    second, other = trainer()
    other.load_state_dict(weights)
    second.restore(saved)
    np.testing.assert_array_equal(second.x, first.x)
    a, b = first.collect_and_update(), second.collect_and_update()
    assert a == b
    np.testing.assert_array_equal(second.x, first.x)
    with pytest.raises(ValueError, match="unseeded"):
        RolloutTrainer(BatchedPPO(AGENTS, 37, 4, cfg), GSVecEnv(ENV, AGENTS, 2, **OPTIONS)).restore(saved)


def test_a_run_warm_started_from_a_rule_records_its_fit_and_resumes_bitwise(tmp_path, monkeypatch):
    """``--imitate greedy`` (ials_zoo.baselines.imitation) on cologne3's three lights reading
    greedy's own count: the fitted actors make greedy's choices, the run records the fit, and a
    resume (past the warm start) neither fits again nor ends elsewhere."""
    from ials_zoo.baselines import shared_ppo

    kwargs = dict(IPPO, env_id="sumo_net_v0", agents="all", total_timesteps=384, eval_every=128,
                  env_options=json.dumps({"net": "cologne3", "max_cycles": 30, "observation": "wave"}),
                  imitate="greedy", imitate_episodes=1, final_eval_episodes=1)
    whole = shared_ppo.main(shared_ppo.Args(**kwargs, out_dir=str(tmp_path / "whole"))), tmp_path / "whole"
    resumed = _stopped_and_resumed(monkeypatch, shared_ppo, tmp_path / "resumed", kwargs)
    assert_same_run(whole, resumed)
    fit, again = (dict(r[0]["training"]["imitation"]) for r in (whole, resumed))
    assert fit.pop("seconds") > 0 and again.pop("seconds") > 0 and fit == again  # the clock is not bitwise
    # 90 choices of small counts (over 28) for 16 hidden units: 0.78 (a uniform choice: about 0.4;
    # the study's fits, 720 decisions of 64 units, make 0.999)
    assert fit["rule"] == "greedy" and fit["decisions"] == 30 and fit["agreement"] > 0.7, fit
    assert "--imitate greedy --imitate-episodes 1" in whole[0]["training"]["reproduce"]["command"]
