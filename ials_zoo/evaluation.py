"""Scoring policies on the global simulator (SPEC §3: "a policy trained anywhere is scored on
the GS"): one agent among scripted neighbours, or every agent at once (the multi-agent track).

Protocol (the same for every leaderboard entry, :data:`PROTOCOL_EPISODES` episodes):

* single-agent track (:func:`evaluate`): the policy controls one agent of the GS; every other
  agent runs its scripted controller;
* multi-agent track (:func:`evaluate_joint`): every agent of the GS (or the listed ones) acts
  with its own policy (a joint policy file holds one set of weights per agent); the score of
  an episode is the mean over agents of each agent's episodic return;
* episode ``i`` is reset with seed ``EVAL_SEED_BASE + i`` (:data:`EVAL_SEED_BASE` = 10,000, far
  from the small seeds used for training), so every policy is scored on the same episodes;
* a stochastic policy draws its actions from a generator seeded with the episode seed
  (:meth:`ials_zoo.policy.PolicyNetwork.act`), so a score is reproducible exactly;
* the score is the mean episodic (undiscounted) return with a 95% BCa bootstrap interval over
  the episodes (:mod:`ials_zoo.stats`).

Policies (:func:`load_policy`):

* ``"random"``: uniform random actions (reference);
* ``"scripted"``: the domain's own scripted controller drives the agent(s) (reference; the GS
  is built with ``scripted_learners=True`` so they are still observed and rewarded);
* ``"rule:NAME"``: a rule-based controller of the domain driving every agent (reference,
  multi-agent track only; :attr:`ials_zoo.core.domains.Domain.rules`, e.g. ``sumo_net_v0``'s
  ``fixed``, ``actuated``, ``greedy`` and ``max_pressure``);
* a policy file (``.safetensors``, :mod:`ials_zoo.policy`) -- weights and JSON, never code;
* an SB3 PPO model zip with its metadata sidecar (``<name>.meta.json``, written by the
  baselines), read safely (weights only, serialized fields ignored);
* ``"module:function"``: an importable callable ``fn(obs) -> action`` (the current directory
  is importable); it reads ``fn.frame_stack`` observations (default 1), stacked as below.
  Such code runs on your machine only: a result of a callable policy can never be submitted.

Frame stacking follows SB3's ``VecFrameStack`` exactly (newest observation last, zeros before
the first observation of an episode), so a model trained with ``VecFrameStack`` sees here what
it saw in training.
"""

from __future__ import annotations

import copy
import hashlib
import importlib
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from ials_zoo.core.domains import domain_ids, get_domain
from ials_zoo.core.extras import study_of
from ials_zoo.core.spaces import sizes_of_env, stack_observations
from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.policy import (
    MAX_FRAME_STACK,
    PolicyNetwork,
    is_policy_file,
    load_policy_file,
    policy_from_sb3_zip,
)
from ials_zoo.single_agent import SingleAgentGS
from ials_zoo.stats import CI_LEVEL, EPISODES_METHOD, bootstrap_interval
from ials_zoo.utils import check_seed, read_json_object

EVAL_SEED_BASE = 10_000
"""Episode ``i`` of an evaluation is reset with seed ``EVAL_SEED_BASE + i``."""
PROTOCOL_EPISODES = 20
"""Episodes of the official protocol (seeds ``EVAL_SEED_BASE .. EVAL_SEED_BASE + 19``)."""

REFERENCE_POLICIES = ("random", "scripted")
RULE_PREFIX = "rule:"
"""A policy spec ``rule:NAME`` is the domain's rule ``NAME`` (:attr:`Domain.rules`)."""
META_SUFFIX = ".meta.json"


def eval_seeds(episodes: int = PROTOCOL_EPISODES, base: int = EVAL_SEED_BASE) -> list[int]:
    """The documented evaluation seed set: ``base, base+1, ..., base+episodes-1``."""
    if isinstance(episodes, bool) or int(episodes) < 1:
        raise BadInput(f"episodes must be >= 1, got {episodes}")
    return [base + i for i in range(int(episodes))]


class _MetricRecorder:
    """Collects a GS's physical metrics (:attr:`Domain.metrics`) episode by episode."""

    def __init__(self, domain, env):
        self.names = list(domain.metrics)
        self.env = env
        self.enabled = False
        self.values: dict[str, list[float]] = {n: [] for n in self.names}

    def episode_started(self) -> None:
        if self.names and not self.enabled:
            self.env.enable_metrics()
            self.enabled = True

    def episode_ended(self) -> None:
        if self.names:
            got = self.env.episode_metrics()
            for n in self.names:
                self.values[n].append(float(got[n]))

    def summary(self) -> dict | None:
        if not self.names:
            return None
        return {n: metric_summary(vals) for n, vals in self.values.items()}


def metric_summary(values: Sequence[float]) -> dict:
    """A metric over an evaluation's episodes: mean and interval (:func:`mean_ci`), median and
    every episode's value (a gridlocked episode shows as a tail, not only in the mean)."""
    mean, lo, hi = mean_ci(values)
    return {"mean": mean, "ci_low": lo, "ci_high": hi, "median": float(np.median(values)),
            "episodes": [float(v) for v in values]}


def mean_ci(values: Sequence[float]) -> tuple[float, float, float]:
    """``(mean, low, high)`` over episodes: the bootstrap interval of :mod:`ials_zoo.stats`."""
    return bootstrap_interval(values, CI_LEVEL)


def sha256_file(path: str | os.PathLike) -> str:
    """Hex sha256 of a file's bytes (identifies the evaluated policy in a result)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def meta_path(model_path: str | os.PathLike) -> Path:
    """The metadata sidecar of an SB3 model zip: ``run/model.zip`` -> ``run/model.meta.json``."""
    p = Path(model_path)
    stem = p.name[: -len(".zip")] if p.name.endswith(".zip") else p.name
    return p.with_name(stem + META_SUFFIX)


# --------------------------------------------------------------------------------------------
# Policies


class Policy:
    """What the evaluator needs from a policy.

    Attributes:
        name: short description (``"random"``, a file name, ``"module:fn"``).
        kind: ``"random"``, ``"scripted"``, ``"rule"``, ``"model"`` or ``"callable"``.
        frame_stack: how many observations the policy reads.
        file, sha256: the file the policy was loaded from and its hash (None otherwise).
        agents: the agents the policy has weights for (None: any agent).
        metadata: the model's metadata (domain, training record, ...), else ``{}``.
    """

    kind = "callable"
    frame_stack = 1
    file: str | None = None
    sha256: str | None = None
    agents: tuple | None = None
    metadata: dict = {}
    name = "policy"
    deterministic = False

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
        return int(self._rng.integers(int(action_space.n)))


class ScriptedPolicy(Policy):
    """The domain's scripted controller (the GS drives the agent; actions are ignored)."""

    kind = "scripted"
    name = "scripted"

    def act(self, obs, action_space):
        return 0


class RulePolicy(Policy):
    """One of the domain's rules (:class:`ials_zoo.core.domains.Rule`) driving every agent; it
    reads the GS, not the observations, so it scores on the multi-agent track only."""

    kind = "rule"

    def __init__(self, name: str, rule):
        self.name = name
        self.rule = rule

    def joint_actor(self, env, agents):
        """``act() -> actions`` in ``agents``' order on the GS ``env`` (zeros where the GS's own
        controller drives them)."""
        if self.rule.make is None:
            zeros = np.zeros(len(agents), np.int64)
            return lambda: zeros
        controller = self.rule.make(env)

        def act():
            chosen = controller(env)
            return np.array([chosen[a] for a in agents], np.int64)

        return act


def load_rule(spec: str, env_id: str | None) -> RulePolicy:
    """``"rule:NAME"``: the domain's rule ``NAME`` (:attr:`Domain.rules`)."""
    name = spec[len(RULE_PREFIX):]
    if env_id is None:
        raise BadInput(f"policy {spec!r} is a rule of a domain: name the domain (--env)")
    rules = get_domain(env_id).rules
    if name not in rules:
        known = ", ".join(f"rule:{k}" for k in rules) or "none"
        raise BadInput(f"{env_id} has no rule {name!r}; its rules: {known}")
    return RulePolicy(name, rules[name])


class CallablePolicy(Policy):
    """Wraps ``fn(obs) -> action``; a ``fn`` with memory has a ``reset(seed)`` method, called
    at every episode start."""

    kind = "callable"

    def __init__(self, fn: Callable, name: str, frame_stack: int | None = None):
        self.fn = fn
        self.name = name
        self.frame_stack = int(frame_stack or getattr(fn, "frame_stack", 1))

    def reset(self, seed):
        if callable(getattr(self.fn, "reset", None)):
            self.fn.reset(seed)

    def act(self, obs, action_space):
        return self.fn(obs)


class NetworkPolicy(Policy):
    """Policy networks of one or more agents (:class:`ials_zoo.policy.PolicyNetwork`)."""

    kind = "model"

    def __init__(self, net: PolicyNetwork, deterministic: bool = False, name: str = "model",
                 file: str | None = None):
        self.net = net
        self.frame_stack = net.frame_stack
        self.deterministic = bool(deterministic)
        self.name = name
        self.file = file
        self.sha256 = sha256_file(file) if file else None
        self.agents = net.agents
        self.metadata = dict(net.metadata)
        self._rng = None

    def for_agents(self, agents) -> NetworkPolicy:
        """The same policy restricted to ``agents`` (each must have weights)."""
        sub = NetworkPolicy(self.net.subset(agents), self.deterministic, self.name)
        sub.file, sub.sha256, sub.metadata = self.file, self.sha256, self.metadata
        return sub

    def reset(self, seed):
        self._rng = np.random.default_rng(seed)

    def act(self, obs, action_space):
        return int(self.act_all(np.asarray(obs)[None])[0])

    def act_all(self, obs: np.ndarray) -> np.ndarray:
        """One action per agent for stacked inputs ``[A, input]``."""
        return self.net.act(obs, self._rng, self.deterministic)


def estimate_evaluation_seconds(env_id: str, episodes: int, **options) -> float:
    """About how long ``episodes`` GS episodes under ``options`` take on 2 cores: their steps
    (:meth:`~ials_zoo.core.domains.Domain.steps_of_episode`) at the domain's own GS step time
    where it states one (``StudySettings.gs_step_seconds``: a real network's cost is its
    map's), else their agent-steps at the training speed the domain's study measured, which
    evaluation beats (an upper estimate; what a re-measure or a long command is bounded by
    before it starts)."""

    domain = get_domain(env_id)
    study = study_of(domain)
    steps = float(episodes) * domain.steps_of_episode(**options)
    step_seconds = study.gs_step_seconds(**options) if study.gs_step_seconds is not None else None
    if step_seconds is not None:
        return steps * float(step_seconds)
    rate = max(float(study.multi_agent_steps_per_second.get("gs", 10_000.0)), 1.0)
    return steps * len(domain.agents(**options)) / rate


SB3_META_MAX_BYTES = 1 << 20


def read_sb3_meta(path: Path, agent: str | None = None) -> dict:
    """An SB3 model's sidecar (``.meta.json``), read as a file someone else may have made
    (:func:`~ials_zoo.utils.read_json_object`) and checked field by field before any of it is
    used: ``sb3_class`` PPO, ``env_id`` a domain, ``agent`` one of its agents (or ``agent``
    given), ``frame_stack`` a whole number in [1, :data:`MAX_FRAME_STACK`]."""
    meta = read_json_object(path, SB3_META_MAX_BYTES, what="SB3 metadata")
    where = f"SB3 metadata {str(path)!r}"
    if meta.get("sb3_class", "PPO") != "PPO":
        raise BadInput(f"{where}: sb3_class {meta.get('sb3_class')!r} is not supported (PPO actor-critic MLP "
                       "policies only)")
    env_id = meta.get("env_id")
    if not isinstance(env_id, str) or env_id not in domain_ids():
        raise BadInput(f"{where}: env_id {env_id!r} is not a domain (known: {', '.join(domain_ids())})")
    frame_stack = meta.get("frame_stack", 1)
    if isinstance(frame_stack, bool) or not isinstance(frame_stack, int) or not 1 <= frame_stack <= MAX_FRAME_STACK:
        raise BadInput(f"{where}: frame_stack must be a whole number in [1, {MAX_FRAME_STACK}], got {frame_stack!r}")
    who = meta.get("agent") or agent
    if not isinstance(who, str) or not who:
        raise BadInput(f"{where}: agent must name an agent of {env_id}, got {meta.get('agent')!r}")
    options = meta.get("env_options") or {}
    # only options a board entry may name (no file a sidecar could point us at)
    options = {k: v for k, v in options.items() if k in get_domain(env_id).gs_options} if isinstance(options, dict) else {}
    try:
        known = get_domain(env_id).agents(**options) if isinstance(options, dict) else ()
    except Exception:  # options the domain refuses: the agent is checked when the policy is used
        known = ()
    if known and who not in known:
        raise BadInput(f"{where}: agent {who!r} is not an agent of {env_id}")
    return meta


def load_model(path: str | os.PathLike, agent: str | None = None) -> NetworkPolicy:
    """A policy file or an SB3 model zip (with its sidecar), loaded without running code."""
    path = Path(path)
    if not path.is_file():
        raise BadInput(f"policy file {str(path)!r} does not exist")
    if is_policy_file(path):
        net = load_policy_file(path)
    elif path.suffix == ".zip":
        mpath = meta_path(path)
        if not mpath.is_file():
            raise BadInput(f"policy file {str(path)!r} has no metadata sidecar {str(mpath)!r} (written by the "
                             "baselines next to the model)")
        meta = read_sb3_meta(mpath, agent)
        provenance = {k: v for k, v in meta.items() if k not in ("format", "sb3_class", "model_sha256", "agents")}
        obs = get_domain(meta["env_id"]).observation_space
        net = policy_from_sb3_zip(path, meta.get("agent") or agent, int(np.prod(obs.shape)),
                                  meta.get("frame_stack", 1), metadata=provenance)
    else:
        raise BadInput(f"policy file {str(path)!r}: expected a .safetensors policy or an SB3 .zip model")
    return NetworkPolicy(net, name=path.name, file=str(path))


def _import_callable(spec: str, frame_stack: int | None) -> CallablePolicy:
    module_name, _, attr = spec.partition(":")
    if os.getcwd() not in sys.path and "" not in sys.path:
        sys.path.insert(0, os.getcwd())  # as `python -m` would: modules of the current folder
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise BadInput(f"policy {spec!r}: cannot import module {module_name!r}: {exc}") from None
    fn = module
    for part in attr.split("."):
        fn = getattr(fn, part, None)
        if fn is None:
            raise BadInput(f"policy {spec!r}: module {module_name!r} has no {attr!r}")
    if not callable(fn):
        raise BadInput(f"policy {spec!r}: {attr!r} is not callable")
    return CallablePolicy(fn, spec, frame_stack)


def load_policy(spec, env_id: str | None = None, agent: str | None = None,
                deterministic: bool = False, frame_stack: int | None = None) -> Policy:
    """Resolve a policy spec: a :class:`Policy`, ``"random"``, ``"scripted"``, ``"rule:NAME"``
    (a rule of ``env_id``'s domain), a policy file, an SB3 model zip or ``"module:function"``
    (see module doc).

    A model is checked against ``env_id`` and ``agent``: a policy is scored on the domain and
    the agent it was trained for (a ValueError says so otherwise). ``frame_stack`` may only
    repeat a model's own."""
    if frame_stack is not None and (isinstance(frame_stack, bool) or int(frame_stack) < 1):
        raise BadInput(f"frame_stack must be >= 1, got {frame_stack}")
    if isinstance(spec, PolicyNetwork):
        spec = NetworkPolicy(spec, deterministic=deterministic, name="policy network")
    if isinstance(spec, Policy):
        pol = spec
        if deterministic and isinstance(pol, NetworkPolicy) and not pol.deterministic:
            # a loaded model asked to act deterministically: never ignore the request silently
            pol = copy.copy(pol)
            pol.deterministic = True
    elif callable(spec):
        pol = CallablePolicy(spec, getattr(spec, "__name__", "callable"), frame_stack)
    elif not isinstance(spec, (str, os.PathLike)):
        raise BadInputType(f"policy must be a path, 'module:function', 'random' or 'scripted', got {spec!r}")
    else:
        spec = os.fspath(spec)
        if spec == "random":
            pol = RandomPolicy()
        elif spec == "scripted":
            pol = ScriptedPolicy()
        elif spec.startswith(RULE_PREFIX):
            pol = load_rule(spec, env_id)
        elif os.path.exists(spec) or spec.endswith((".zip", ".safetensors")):
            pol = load_model(spec, agent)
            pol.deterministic = bool(deterministic)
        elif ":" in spec:
            pol = _import_callable(spec, frame_stack)
        else:
            raise BadInput(f"policy {spec!r} is neither 'random', 'scripted', an existing policy file, nor "
                             "'module:function'")
    if pol.kind == "model":
        trained_env = pol.metadata.get("env_id")
        if env_id is not None and trained_env not in (None, env_id):
            raise BadInput(f"policy {pol.name!r} was trained for {trained_env}, not {env_id}")
        if agent is not None and agent not in pol.agents:
            raise BadInput(f"policy {pol.name!r} was trained for {', '.join(pol.agents)}, not {agent!r}; a "
                             "policy is scored on the agent it was trained for")
        if frame_stack is not None and int(frame_stack) != pol.frame_stack:
            raise BadInput(f"frame_stack {frame_stack} contradicts the model's ({pol.frame_stack})")
    return pol


class FrameStack:
    """Stacks the last ``n`` observations exactly like SB3's ``VecFrameStack`` on a 1-D Box:
    concatenated on the last axis, newest last, zeros before the episode's first observation.
    Works on one observation or a batch (``[..., obs]``)."""

    def __init__(self, n: int):
        if int(n) < 1:
            raise BadInput(f"frame_stack must be >= 1, got {n}")
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
        self._buf[..., : -self._width] = self._buf[..., self._width:]
        self._buf[..., -self._width:] = obs
        return self._buf.copy()


# --------------------------------------------------------------------------------------------
# Evaluation


@dataclass
class EvaluationResult:
    """The score of a policy on the GS.

    Attributes:
        env_id: the domain.
        agent: the agent scored (single-agent track), or None (multi-agent track).
        agents: the agents whose returns make the score (``[agent]`` on the single-agent track).
        policy, policy_kind: the policy's name and kind (random | scripted | model | callable).
        policy_file, policy_sha256: the evaluated file and its hash (None for references).
        frame_stack, deterministic: how the policy was run.
        seeds: the episode seeds; returns: the score of each episode (the agent's return, or
            the mean over agents of their returns).
        per_agent_returns: ``{agent: [return per episode]}`` (multi-agent track).
        mean, ci_low, ci_high: mean and its 95% bootstrap interval over episodes.
        episode_length: steps per episode; seconds: wall-clock of the evaluation.
        options: GS options.
        metrics: ``{name: {"mean", "ci_low", "ci_high"}}``, the domain's physical metrics
            over the episodes (bootstrap intervals), or None where the domain has none.
    """

    env_id: str
    agent: str | None
    agents: list
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
    per_agent_returns: dict | None = None
    ci_method: str = EPISODES_METHOD
    metrics: dict | None = None

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


def _check_seeds(seeds, episodes) -> list[int]:
    seeds = list(eval_seeds(episodes) if seeds is None else seeds)
    if not seeds:
        raise BadInput("seeds must not be empty")
    return [check_seed(s, "evaluation seed", allow_none=False) for s in seeds]


def evaluate(env_id: str, agent: str, policy, episodes: int = PROTOCOL_EPISODES,
             seeds: Sequence[int] | None = None, deterministic: bool = False,
             frame_stack: int | None = None, progress: bool = False, **options) -> EvaluationResult:
    """Score ``policy`` for ``agent`` on the GS of ``env_id``, every other agent scripted.

    Args:
        policy: anything :func:`load_policy` accepts.
        episodes: number of episodes when ``seeds`` is not given (seeds ``10000 + i``).
        seeds: explicit episode seeds (overrides ``episodes``).
        deterministic: take the policy's most likely action instead of sampling (models).
        frame_stack: the callable policy's frame stack (a model's own only).
        **options: GS options (passed to the domain's ``parallel_env``).
    """
    domain = get_domain(env_id)
    domain.check_agent(agent, **options)
    pol = load_policy(policy, env_id, agent, deterministic=deterministic, frame_stack=frame_stack)
    if pol.kind == "rule":
        raise BadInput(f"rule:{pol.name} drives every agent: it scores on the multi-agent track (--joint)")
    if isinstance(pol, NetworkPolicy) and pol.agents != (agent,):
        pol = pol.for_agents([agent])
    seeds = _check_seeds(seeds, episodes)
    stack = FrameStack(pol.frame_stack)
    env = SingleAgentGS(env_id, agent, scripted_learner=(pol.kind == "scripted"), **options)
    recorder = _MetricRecorder(domain, env.parallel)
    start = time.perf_counter()
    iterator = seeds
    if progress:
        iterator = tqdm(seeds, desc=f"evaluate {agent}", unit="episode")
    try:
        returns, length = [], 0
        for seed in iterator:
            pol.reset(int(seed))
            obs, _ = env.reset(seed=int(seed))
            recorder.episode_started()
            obs = stack.reset(obs)
            total, steps, done = 0.0, 0, False
            while not done:
                raw, reward, terminated, truncated, _ = env.step(pol.act(obs, env.action_space))
                obs = stack.step(raw)
                total += reward
                steps += 1
                done = terminated or truncated
            recorder.episode_ended()
            returns.append(float(total))
            length = steps
    finally:
        env.close()
    mean, lo, hi = mean_ci(returns)
    return EvaluationResult(
        env_id=env_id, agent=agent, agents=[agent], policy=pol.name, policy_kind=pol.kind,
        policy_file=pol.file, policy_sha256=pol.sha256, frame_stack=pol.frame_stack,
        deterministic=bool(pol.deterministic) if pol.kind == "model" else False,
        seeds=[int(s) for s in seeds], returns=returns, mean=mean, ci_low=lo, ci_high=hi,
        episode_length=length, seconds=time.perf_counter() - start, options=dict(options),
        metrics=recorder.summary(),
    )


def _check_fits(pol: NetworkPolicy, sizes, agents) -> None:
    """A BadInput unless the policy reads these agents' (padded) observations and has each one's actions."""
    net = pol.net
    have = tuple(net.action_counts or (net.n_actions,) * len(agents))
    need = tuple(sizes.action_counts or (sizes.n_actions,) * len(agents))
    if net.obs_size != sizes.obs_size or have != need:
        raise BadInput(f"policy {pol.name!r} reads observations of {net.obs_size} with {list(have)} actions per agent; "
                       f"these agents have observations of {sizes.obs_size} and {list(need)} actions")


def evaluate_joint(env_id: str, policy, agents=None, episodes: int = PROTOCOL_EPISODES,
                   seeds: Sequence[int] | None = None, deterministic: bool = False,
                   progress: bool = False, **options) -> EvaluationResult:
    """Score a joint policy on the GS of ``env_id`` with ``agents`` (default: all) acting at
    once, each with its own policy (multi-agent track; module docstring).

    ``policy``: a joint policy file (weights for every agent), a :class:`NetworkPolicy`,
    ``"random"``, ``"scripted"`` or ``"rule:NAME"`` (a rule of the domain)."""
    domain = get_domain(env_id)
    pol = load_policy(policy, env_id, deterministic=deterministic)
    if pol.kind == "callable":
        raise BadInput("the multi-agent track scores joint policy files, 'random', 'scripted' or 'rule:NAME'")
    if agents is None:
        agents = list(pol.agents) if pol.kind == "model" else domain.agents(**options)
    agents = domain.check_agents(agents, **options)
    if isinstance(pol, NetworkPolicy):
        missing = [a for a in agents if a not in pol.agents]
        if missing:
            raise BadInput(f"policy {pol.name!r} has no weights for {missing}")
        if tuple(agents) != pol.agents:
            pol = pol.for_agents(agents)
    seeds = _check_seeds(seeds, episodes)
    scripted = {"scripted_learners": True} if pol.kind == "scripted" else {}
    if pol.kind == "rule":  # the rule's own GS options: a part of the policy, not of the protocol
        scripted = dict(pol.rule.env_options)
    env = domain.parallel_env(learners=agents, **scripted, **options)
    try:
        sizes = sizes_of_env(env, agents)  # agents with spaces of their own: padded, each its own actions
        if isinstance(pol, NetworkPolicy):
            _check_fits(pol, sizes, agents)
        # the shared-space draw stays as it was (entries on the board re-measure bitwise)
        counts = sizes.n_actions if sizes.action_counts is None else np.asarray(sizes.action_counts)
        act = _joint_actor(pol, env, agents, counts)
    except BaseException:
        env.close()
        raise
    recorder = _MetricRecorder(domain, env)
    stack = FrameStack(pol.frame_stack)
    width = sizes.obs_size
    start = time.perf_counter()
    iterator = seeds
    if progress:
        iterator = tqdm(seeds, desc=f"evaluate {len(agents)} agents", unit="episode")
    per_agent = np.zeros((len(agents), len(seeds)))
    length = 0
    try:
        for e, seed in enumerate(iterator):
            pol.reset(int(seed))
            obs, _ = env.reset(seed=int(seed))
            recorder.episode_started()
            x = stack.reset(stack_observations(obs, agents, width))
            steps = 0
            while env.agents:
                obs, rewards, _, _, _ = env.step({a: int(u) for a, u in zip(agents, act(x))})
                per_agent[:, e] += [rewards[a] for a in agents]
                steps += 1
                if env.agents:
                    x = stack.step(stack_observations(obs, agents, width))
            recorder.episode_ended()
            length = steps
    finally:
        env.close()
    returns = per_agent.mean(axis=0).tolist()
    mean, lo, hi = mean_ci(returns)
    return EvaluationResult(
        env_id=env_id, agent=None, agents=list(agents), policy=pol.name, policy_kind=pol.kind,
        policy_file=pol.file, policy_sha256=pol.sha256, frame_stack=pol.frame_stack,
        deterministic=bool(pol.deterministic) if pol.kind == "model" else False,
        seeds=[int(s) for s in seeds], returns=returns, mean=mean, ci_low=lo, ci_high=hi,
        episode_length=length, seconds=time.perf_counter() - start, options=dict(options),
        per_agent_returns={a: per_agent[i].tolist() for i, a in enumerate(agents)},
        metrics=recorder.summary(),
    )


def _joint_actor(pol: Policy, env, agents, counts):
    """``act(x) -> every agent's action`` from the stacked observations ``x``: the network's, a
    uniform draw (from the generator the episode's seed reset), the rule's (it reads the GS), or
    zeros where the GS's own controller drives the agents."""
    if isinstance(pol, NetworkPolicy):
        return pol.act_all
    if pol.kind == "random":
        return lambda x: pol._rng.integers(counts, size=len(agents))
    if pol.kind == "rule":
        rule = pol.joint_actor(env, agents)
        return lambda x: rule()
    zeros = np.zeros(len(agents), np.int64)
    return lambda x: zeros


def _evaluate_worker(env_id, agent, policy, kwargs):
    """:func:`evaluate` (``agent``) or :func:`evaluate_joint` (``agent=None``) in a worker."""
    import torch

    torch.set_num_threads(1)
    if agent is None:
        return evaluate_joint(env_id, policy, **kwargs)
    return evaluate(env_id, agent, policy, **kwargs)


__all__ = [
    "EVAL_SEED_BASE",
    "PROTOCOL_EPISODES",
    "CallablePolicy",
    "EvaluationResult",
    "FrameStack",
    "NetworkPolicy",
    "Policy",
    "RandomPolicy",
    "RulePolicy",
    "ScriptedPolicy",
    "eval_seeds",
    "evaluate",
    "evaluate_joint",
    "load_model",
    "load_policy",
    "mean_ci",
    "estimate_evaluation_seconds",
    "meta_path",
    "sha256_file",
]
