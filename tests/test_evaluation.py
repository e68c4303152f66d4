"""The GS evaluator: statistics, frame stacking, determinism, policy specs, the command."""

import json
import math
import textwrap

import numpy as np
import pytest

from ials_zoo.evaluation import (
    EVAL_SEED_BASE,
    FrameStack,
    eval_seeds,
    evaluate,
    load_policy,
    mean_ci,
)
from ials_zoo.single_agent import SingleAgentGS, make_gs_vec_env
from ials_zoo.stats import bootstrap_interval, t_interval

ENV, AGENT = "warehouse_v0", "robot_20"


def test_t_interval_over_seeds_matches_tables():
    x = [1.0, 2.0, 3.0, 4.0, 10.0]
    mean, lo, hi = t_interval(x)
    half = 2.776445 * np.std(x, ddof=1) / math.sqrt(5)  # t(0.975, 4) from the tables
    assert mean == pytest.approx(4.0)
    assert (lo, hi) == pytest.approx((4.0 - half, 4.0 + half), abs=1e-5)
    assert t_interval([3.5]) == (3.5, 3.5, 3.5)
    with pytest.raises(ValueError, match="non-empty"):
        t_interval([])
    with pytest.raises(ValueError, match="finite"):
        t_interval([1.0, float("nan")])


def test_bootstrap_interval_over_episodes_respects_the_data():
    # Non-negative returns, mostly 0: the t interval reaches below 0, the bootstrap does not.
    x = [0.0] * 7 + [1.2, 0.5, 3.0]
    _, t_lo, _ = t_interval(x)
    mean, lo, hi = bootstrap_interval(x)
    assert t_lo < 0 <= lo < mean < hi <= max(x)
    assert bootstrap_interval(x) == (mean, lo, hi)  # deterministic: a fixed resampling seed
    assert mean_ci(x) == (mean, lo, hi)  # the evaluator's interval
    assert bootstrap_interval([2.0, 2.0, 2.0]) == (2.0, 2.0, 2.0)


def test_eval_seeds_are_documented_set():
    assert eval_seeds(3) == [EVAL_SEED_BASE, EVAL_SEED_BASE + 1, EVAL_SEED_BASE + 2]
    with pytest.raises(ValueError, match="episodes"):
        eval_seeds(0)


def test_single_agent_gs_ends_by_truncation():
    env = SingleAgentGS(ENV, AGENT, max_cycles=7)
    obs, _ = env.reset(seed=1)
    assert obs.shape == env.observation_space.shape and obs.dtype == np.float32
    for t in range(7):
        obs, r, term, trunc, _ = env.step(env.action_space.sample())
        assert term is False
        assert trunc is (t == 6)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(0)
    with pytest.raises(ValueError, match="robot_99"):
        SingleAgentGS(ENV, "robot_99")


def test_gs_vec_env_marks_time_limit_for_bootstrapping():
    venv = make_gs_vec_env(ENV, AGENT, n_envs=2, max_cycles=4)
    venv.reset()
    for t in range(4):
        _, _, dones, infos = venv.step(np.zeros(2, dtype=np.int64))
    assert dones.all()
    for info in infos:
        assert info["TimeLimit.truncated"] is True
        assert info["terminal_observation"].shape == venv.observation_space.shape
    venv.close()


def test_frame_stack_matches_sb3_vec_frame_stack():
    from stable_baselines3.common.vec_env import VecFrameStack

    venv = VecFrameStack(make_gs_vec_env(ENV, AGENT, n_envs=1, max_cycles=6), 4)
    venv.seed(5)
    env = SingleAgentGS(ENV, AGENT, max_cycles=6)
    stack = FrameStack(4)
    ours = stack.reset(env.reset(seed=5)[0])
    theirs = venv.reset()[0]
    np.testing.assert_array_equal(ours, theirs)
    rng = np.random.default_rng(0)
    for _ in range(6):
        a = int(rng.integers(4))
        raw, *_ = env.step(a)
        ours = stack.step(raw)
        theirs, _, dones, infos = venv.step(np.array([a]))
        expected = infos[0]["terminal_observation"] if dones[0] else theirs[0]
        np.testing.assert_array_equal(ours, expected)
    venv.close()


def test_evaluation_is_deterministic_for_a_fixed_seed_set():
    for policy in ("random", "scripted"):
        a = evaluate(ENV, AGENT, policy, episodes=4)
        b = evaluate(ENV, AGENT, policy, episodes=4)
        assert a.returns == b.returns and a.mean == b.mean
        assert a.seeds == eval_seeds(4)
        assert a.episode_length == 100
    other = evaluate(ENV, AGENT, "random", seeds=[1, 2, 3, 4])
    assert other.returns != evaluate(ENV, AGENT, "random", episodes=4).returns


def test_scripted_reference_beats_random():
    scripted = evaluate(ENV, AGENT, "scripted", episodes=5)
    random = evaluate(ENV, AGENT, "random", episodes=5)
    assert scripted.ci_low > random.ci_high
    assert scripted.policy_sha256 is None and random.policy_file is None


def test_callable_policy_spec(tmp_path, monkeypatch):
    (tmp_path / "my_policies.py").write_text(textwrap.dedent("""
        import numpy as np
        SEEN = []
        def go_up(obs):
            SEEN.append(np.shape(obs))
            return 0
        def stacked(obs):
            SEEN.append(np.shape(obs))
            return 1
        stacked.frame_stack = 3
    """))
    # importable from the folder the user is in, as `python -m` would have it
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("sys.path", [p for p in __import__("sys").path if p not in ("", str(tmp_path))])
    res = evaluate(ENV, AGENT, "my_policies:go_up", episodes=1)
    import my_policies

    my_policies.SEEN.clear()

    res = evaluate(ENV, AGENT, "my_policies:go_up", episodes=2)
    assert res.policy_kind == "callable" and res.frame_stack == 1
    assert set(my_policies.SEEN) == {(37,)}
    my_policies.SEEN.clear()
    evaluate(ENV, AGENT, "my_policies:stacked", episodes=1)
    assert set(my_policies.SEEN) == {(3 * 37,)}


@pytest.mark.parametrize("spec,match", [
    ("nonexistent_module_xyz:fn", "cannot import"),
    ("json:no_such_function", "has no"),
    ("/no/such/model.zip", "does not exist"),
    ("/no/such/policy.safetensors", "does not exist"),
    ("greedy", "neither"),
])
def test_bad_policy_specs_are_named(spec, match):
    with pytest.raises(ValueError, match=match):
        load_policy(spec)


def test_evaluate_command_writes_a_valid_result(tmp_path):
    from ials_zoo.cli import main
    from ials_zoo.leaderboard import load_result

    out = tmp_path / "r.json"
    rc = main(["evaluate", "--env", ENV, "--agent", AGENT, "--policy", "scripted",
               "--episodes", "3", "--out", str(out), "--no-progress"])
    assert rc == 0
    data = load_result(out)
    assert data["algorithm"] == "scripted" and data["training"] is None
    assert data["evaluation"]["seeds"] == eval_seeds(3)
    assert data["scores"][0]["returns"] == evaluate(ENV, AGENT, "scripted", episodes=3).returns
    assert json.loads(out.read_text()) == data
    assert main(["evaluate", "--env", "nope_v0", "--policy", "random", "--no-progress"]) == 2
