"""Scoring a policy on the global simulator (SPEC §3: "a policy trained anywhere is scored on
the GS, with the other agents scripted").

Protocol (the same for every leaderboard entry):

* the policy controls one agent of the GS; every other agent runs its scripted controller;
* episode ``i`` (``i = 0 .. episodes-1``) is reset with seed ``EVAL_SEED_BASE + i``
  (:data:`EVAL_SEED_BASE` = 10,000, far from the small seeds used for training), so every
  policy is scored on the same episodes;
* a stochastic policy samples its actions from a generator seeded with the episode seed, so a
  score is reproducible bit for bit for a fixed seed set (on the same software);
* the score is the mean episodic (undiscounted) return over the episodes, with a 95%
  confidence interval from the Student t-distribution over episodes:
  ``mean +- t_{0.975, n-1} * s / sqrt(n)`` with ``s`` the sample standard deviation
  (``ddof=1``); with a single episode the interval is ``[mean, mean]`` (undefined width is
  reported as zero and flagged by ``n == 1``).

Policies (:func:`load_policy`):

* ``"random"``: uniform random actions (reference);
* ``"scripted"``: the domain's own scripted controller drives the agent (reference; the GS is
  built with ``scripted_learners=True`` so the agent is still observed and rewarded);
* a path to a saved baseline model (SB3 ``.zip``) with its metadata sidecar
  (``<name>.meta.json``, written by the baselines): the frame stack comes from the metadata;
* ``"package.module:function"``: any importable callable ``fn(obs) -> action``; it reads the
  current observation unless it has an integer attribute ``frame_stack``.

Frame stacking follows SB3's ``VecFrameStack`` exactly (newest observation last, zeros before
the first observation of an episode), so a model trained with ``VecFrameStack`` sees here what
it saw in training.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ials_zoo.core.domains import get_domain

EVAL_SEED_BASE = 10_000
"""Episode ``i`` of an evaluation is reset with seed ``EVAL_SEED_BASE + i``."""

CI_LEVEL = 0.95
REFERENCE_POLICIES = ("random", "scripted")
META_SUFFIX = ".meta.json"


def eval_seeds(episodes: int, base: int = EVAL_SEED_BASE) -> list[int]:
    """The documented evaluation seed set: ``base, base+1, ..., base+episodes-1``."""
    if int(episodes) < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    return [base + i for i in range(int(episodes))]


# --------------------------------------------------------------------------------------------
# Statistics (no scipy in the dependencies: the t quantile is computed here).


def _betacf(a: float, b: float, x: float) -> float:
    # Continued fraction of the regularised incomplete beta function (modified Lentz).
    tiny = 1e-300
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 500):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-15:
            break
    return h


def _betainc(a: float, b: float, x: float) -> float:
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    lbeta = math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b)
    front = math.exp(lbeta + a * math.log(x) + b * math.log1p(-x))
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _betacf(a, b, x) / a
    return 1.0 - front * _betacf(b, a, 1.0 - x) / b


def student_t_cdf(t: float, df: float) -> float:
    """CDF of Student's t-distribution with ``df`` degrees of freedom."""
    if df <= 0:
        raise ValueError(f"df must be > 0, got {df}")
    tail = 0.5 * _betainc(df / 2.0, 0.5, df / (df + t * t))
    return 1.0 - tail if t >= 0 else tail


def student_t_ppf(q: float, df: float) -> float:
    """Quantile of Student's t-distribution (bisection on :func:`student_t_cdf`)."""
    if not 0.0 < q < 1.0:
        raise ValueError(f"q must be in (0, 1), got {q}")
    if q < 0.5:
        return -student_t_ppf(1.0 - q, df)
    lo, hi = 0.0, 1.0
    while student_t_cdf(hi, df) < q:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if student_t_cdf(mid, df) < q:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-12:
            break
    return 0.5 * (lo + hi)


def mean_ci(values: Sequence[float], level: float = CI_LEVEL) -> tuple[float, float, float]:
    """``(mean, ci_low, ci_high)``: the t-interval of the mean of ``values`` (module doc)."""
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 1 or x.size == 0:
        raise ValueError(f"need a non-empty 1-D sequence of values, got shape {x.shape}")
    mean = float(x.mean())
    if x.size == 1:
        return mean, mean, mean
    half = student_t_ppf(0.5 + level / 2.0, x.size - 1) * float(x.std(ddof=1)) / math.sqrt(x.size)
    return mean, mean - half, mean + half


# --------------------------------------------------------------------------------------------
# Policies


def sha256_file(path: str | os.PathLike) -> str:
    """Hex sha256 of a file's bytes (identifies the evaluated policy in a result)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def meta_path(model_path: str | os.PathLike) -> Path:
    """The metadata sidecar of a saved model: ``run/model.zip`` -> ``run/model.meta.json``."""
    p = Path(model_path)
    stem = p.name[: -len(".zip")] if p.name.endswith(".zip") else p.name
    return p.with_name(stem + META_SUFFIX)


class Policy:
    """What the evaluator needs from a policy.

    Attributes:
        name: short description (``"random"``, a file name, ``"module:fn"``).
        kind: ``"random"``, ``"scripted"``, ``"model"`` or ``"callable"``.
        frame_stack: how many observations the policy reads (stacked as ``VecFrameStack``).
        file: the file the policy was loaded from (None for reference policies).
        sha256: that file's sha256 (None when there is no file).
        metadata: the model's metadata (baselines), else ``{}``.
    """

    kind = "callable"
    frame_stack = 1
    file: str | None = None
    sha256: str | None = None
    metadata: dict = {}
    name = "policy"

    def reset(self, seed: int) -> None:
        """Called at the start of each episode with the episode seed."""

    def act(self, obs: np.ndarray, action_space) -> Any:
        raise NotImplementedError


class RandomPolicy(Policy):
    """Uniform random actions; seeded per episode."""

    kind = "random"
    name = "random"

    def reset(self, seed):
        self._rng = np.random.default_rng(seed)

    def act(self, obs, action_space):
        if hasattr(action_space, "n"):
            return int(self._rng.integers(int(action_space.n)))
        action_space.seed(int(self._rng.integers(2**31)))
        return action_space.sample()


class ScriptedPolicy(Policy):
    """The domain's scripted controller (the GS drives the agent; actions are ignored)."""

    kind = "scripted"
    name = "scripted"

    def act(self, obs, action_space):
        return 0  # ignored: the GS is built with scripted_learners=True


class CallablePolicy(Policy):
    """Wraps ``fn(obs) -> action``."""

    kind = "callable"

    def __init__(self, fn: Callable, name: str, frame_stack: int | None = None):
        self.fn = fn
        self.name = name
        self.frame_stack = int(frame_stack or getattr(fn, "frame_stack", 1))

    def act(self, obs, action_space):
        return self.fn(obs)


class SB3Policy(Policy):
    """An SB3 model (any object with ``predict(obs, deterministic)``).

    A stochastic policy samples with torch's generator, seeded at each episode start, so an
    evaluation is reproducible for a fixed seed set.
    """

    kind = "model"

    def __init__(self, model, frame_stack: int = 1, deterministic: bool = False,
                 name: str = "model", file: str | None = None, metadata: dict | None = None):
        self.model = model
        self.frame_stack = int(frame_stack)
        self.deterministic = bool(deterministic)
        self.name = name
        self.file = file
        self.sha256 = sha256_file(file) if file else None
        self.metadata = dict(metadata or {})

    def reset(self, seed):
        import torch

        torch.manual_seed(seed)

    def act(self, obs, action_space):
        action, _ = self.model.predict(obs, deterministic=self.deterministic)
        return action.item() if np.ndim(action) == 0 or np.size(action) == 1 else action


def load_model(path: str | os.PathLike):
    """Load a saved baseline model and its metadata sidecar: ``(model, metadata)``.

    Only SB3 is needed (not the training code): schedules are replaced by constants since
    the model is only used for prediction.
    """
    import stable_baselines3

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"policy file {str(path)!r} does not exist")
    mpath = meta_path(path)
    if not mpath.is_file():
        raise ValueError(
            f"policy file {str(path)!r} has no metadata sidecar {str(mpath)!r} (written by the "
            "baselines next to the model)"
        )
    try:
        meta = json.loads(mpath.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"metadata {str(mpath)!r} is not valid JSON: {exc}") from None
    cls_name = meta.get("sb3_class", "PPO")
    cls = getattr(stable_baselines3, cls_name, None)
    if cls is None:
        raise ValueError(f"metadata {str(mpath)!r}: unknown sb3_class {cls_name!r}")
    custom = {"learning_rate": 0.0, "lr_schedule": lambda _: 0.0, "clip_range": lambda _: 0.0}
    model = cls.load(str(path), device="cpu", custom_objects=custom)
    return model, meta


def load_policy(spec, env_id: str | None = None, agent: str | None = None,
                deterministic: bool = False, frame_stack: int | None = None) -> Policy:
    """Resolve a policy spec: a :class:`Policy`, ``"random"``, ``"scripted"``, a model path, or
    ``"module:function"`` (see module doc).

    When a model's metadata names a domain/agent that differs from ``env_id``/``agent``, a
    ValueError says so (a policy is scored on the agent it was trained for).
    """
    if isinstance(spec, Policy):
        return spec
    if callable(spec):
        return CallablePolicy(spec, getattr(spec, "__name__", "callable"), frame_stack)
    if not isinstance(spec, (str, os.PathLike)):
        raise TypeError(f"policy must be a path, 'module:function', 'random' or 'scripted', got {spec!r}")
    spec = os.fspath(spec)
    if spec == "random":
        return RandomPolicy()
    if spec == "scripted":
        return ScriptedPolicy()
    if os.path.exists(spec) or spec.endswith(".zip"):
        model, meta = load_model(spec)
        for key, want in (("env_id", env_id), ("agent", agent)):
            if want is not None and meta.get(key) not in (None, want) and not (
                key == "agent" and want in meta.get("agents", [])
            ):
                raise ValueError(
                    f"policy {spec!r} was trained for {key}={meta.get(key)!r}, not {want!r}"
                )
        return SB3Policy(model, frame_stack=int(frame_stack or meta.get("frame_stack", 1)),
                         deterministic=deterministic, name=Path(spec).name, file=spec,
                         metadata=meta)
    if ":" in spec:
        module_name, _, attr = spec.partition(":")
        try:
            module = importlib.import_module(module_name)
        except ImportError as exc:
            raise ValueError(f"policy {spec!r}: cannot import module {module_name!r}: {exc}") from None
        fn = module
        for part in attr.split("."):
            fn = getattr(fn, part, None)
            if fn is None:
                raise ValueError(f"policy {spec!r}: module {module_name!r} has no {attr!r}")
        if not callable(fn):
            raise ValueError(f"policy {spec!r}: {attr!r} is not callable")
        return CallablePolicy(fn, spec, frame_stack)
    raise ValueError(
        f"policy {spec!r} is neither 'random', 'scripted', an existing model file, nor "
        "'module:function'"
    )


class FrameStack:
    """Stacks the last ``n`` observations exactly like SB3's ``VecFrameStack`` on a 1-D Box:
    concatenated on the last axis, newest last, zeros before the episode's first observation."""

    def __init__(self, n: int):
        if int(n) < 1:
            raise ValueError(f"frame_stack must be >= 1, got {n}")
        self.n = int(n)
        self._buf = None

    def reset(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        if self.n == 1:
            return obs
        self._width = obs.shape[-1]
        self._buf = np.zeros(obs.shape[:-1] + (self._width * self.n,), dtype=np.float32)
        self._buf[..., -self._width:] = obs
        return self._buf.copy()

    def step(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        if self.n == 1:
            return obs
        self._buf = np.roll(self._buf, -self._width, axis=-1)
        self._buf[..., -self._width:] = obs
        return self._buf.copy()


# --------------------------------------------------------------------------------------------
# Evaluation


@dataclass
class EvaluationResult:
    """The score of one policy on the GS.

    Attributes:
        env_id, agent: what was evaluated.
        policy: the policy's name; policy_kind: random | scripted | model | callable.
        policy_file, policy_sha256: the evaluated file and its hash (None for references).
        frame_stack, deterministic: how the policy was run.
        seeds: the episode seeds; returns: the episodic return of each.
        mean, ci_low, ci_high: mean return and its 95% t-interval (module doc).
        episode_length: steps per episode; seconds: wall-clock of the evaluation.
    """

    env_id: str
    agent: str
    policy: str
    policy_kind: str
    policy_file: str | None
    policy_sha256: str | None
    frame_stack: int
    deterministic: bool
    seeds: list[int]
    returns: list[float]
    mean: float
    ci_low: float
    ci_high: float
    episode_length: int
    seconds: float
    options: dict = field(default_factory=dict)

    @property
    def episodes(self) -> int:
        return len(self.returns)

    @property
    def half_width(self) -> float:
        return (self.ci_high - self.ci_low) / 2.0

    def to_dict(self) -> dict:
        d = asdict(self)
        d["episodes"] = self.episodes
        return d


def evaluate(env_id: str, agent: str, policy, episodes: int = 10,
             seeds: Sequence[int] | None = None, deterministic: bool = False,
             frame_stack: int | None = None, progress: bool = False,
             **options) -> EvaluationResult:
    """Score ``policy`` for ``agent`` on the GS of ``env_id`` (protocol in the module doc).

    Args:
        policy: anything :func:`load_policy` accepts.
        episodes: number of episodes when ``seeds`` is not given (seeds ``10000 + i``).
        seeds: explicit episode seeds (overrides ``episodes``).
        deterministic: take the policy's most likely action instead of sampling (models only).
        frame_stack: override the policy's frame stack.
        **options: GS options (passed to the domain's ``parallel_env``).
    """
    import time

    from ials_zoo.single_agent import SingleAgentGS, check_agent

    get_domain(env_id)  # clear error for an unknown domain
    check_agent(env_id, agent)
    pol = load_policy(policy, env_id, agent, deterministic=deterministic, frame_stack=frame_stack)
    seeds = list(eval_seeds(episodes) if seeds is None else seeds)
    if not seeds:
        raise ValueError("seeds must not be empty")
    stack = FrameStack(pol.frame_stack)
    env = SingleAgentGS(env_id, agent, scripted_learner=(pol.kind == "scripted"), **options)
    start = time.perf_counter()
    iterator = seeds
    if progress:
        from tqdm import tqdm

        iterator = tqdm(seeds, desc=f"evaluate {agent}", unit="ep")
    import contextlib

    rng_guard = contextlib.nullcontext()
    if pol.kind == "model":
        import torch

        # SB3Policy reseeds torch per episode: keep the caller's (a training run's) stream.
        rng_guard = torch.random.fork_rng(devices=[])
    try:
        with rng_guard:
            returns, length = _run_episodes(env, pol, stack, iterator)
    finally:
        env.close()
    mean, lo, hi = mean_ci(returns)
    return EvaluationResult(
        env_id=env_id, agent=agent, policy=pol.name, policy_kind=pol.kind,
        policy_file=pol.file, policy_sha256=pol.sha256, frame_stack=pol.frame_stack,
        deterministic=bool(deterministic) if pol.kind == "model" else False,
        seeds=[int(s) for s in seeds], returns=returns, mean=mean, ci_low=lo, ci_high=hi,
        episode_length=length, seconds=time.perf_counter() - start, options=dict(options),
    )


def _run_episodes(env, pol: Policy, stack: FrameStack, seeds) -> tuple[list[float], int]:
    returns, length = [], 0
    for seed in seeds:
        pol.reset(int(seed))
        obs, _ = env.reset(seed=int(seed))
        obs = stack.reset(obs)
        total, steps, done = 0.0, 0, False
        while not done:
            raw, reward, terminated, truncated, _ = env.step(pol.act(obs, env.action_space))
            obs = stack.step(raw)
            total += reward
            steps += 1
            done = terminated or truncated
        returns.append(float(total))
        length = steps
    return returns, length


def evaluate_in_subprocess(env_id: str, agent: str, policy_path: str, start_method="forkserver",
                           **kwargs) -> EvaluationResult:
    """:func:`evaluate` a saved model in a fresh worker process (for SUMO domains, whose GS
    must not share this process's libsumo simulation). Blocks until done."""
    import concurrent.futures
    import multiprocessing

    ctx = multiprocessing.get_context(start_method)
    with concurrent.futures.ProcessPoolExecutor(max_workers=1, mp_context=ctx) as pool:
        return pool.submit(_evaluate_worker, env_id, agent, str(policy_path), kwargs).result()


def _evaluate_worker(env_id, agent, policy_path, kwargs):
    import torch

    torch.set_num_threads(1)
    return evaluate(env_id, agent, policy_path, **kwargs)
