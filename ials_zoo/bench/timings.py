"""The bench's timings: each returns seconds per unit (per GS step, per agent-step, per sample) of
one simulator or learner of a domain, measured with uniformly random actions drawn before the
clock starts. The domain is resolved once by the caller and passed in."""

from __future__ import annotations

import time

import numpy as np
import torch

from ials_zoo.baselines import dials
from ials_zoo.baselines.multiagent import fill_update_size, frame_stack_of, ppo_config
from ials_zoo.core.domains import Domain
from ials_zoo.influence.ials import make_ials, make_ials_vec_env
from ials_zoo.influence.multi import make_ials_parallel_env, make_multi_agent_ials
from ials_zoo.learners.batched_ppo import BatchedPPO, PPOConfig


def gs_seconds(domain: Domain, learners, steps: int, seed: int, **options) -> float:
    """Seconds per GS step with uniformly random actions for ``learners`` (others scripted)."""
    env = domain.parallel_env(learners=learners, **options)
    try:
        rng = np.random.default_rng(seed)
        env.reset(seed=seed)
        n = int(env.action_space(env.possible_agents[0]).n)
        done, t0 = 0, time.perf_counter()
        while done < steps:
            if not env.agents:
                env.reset(seed=int(rng.integers(2**31)))
            acts = rng.integers(n, size=len(env.agents))
            env.step({a: int(u) for a, u in zip(env.agents, acts)})
            done += 1
        return (time.perf_counter() - t0) / steps
    finally:
        env.close()


def ials_seconds(domain: Domain, agent: str, steps: int, seed: int, predictor, **options) -> float:
    """Seconds per step of one agent's IALS (Gymnasium API)."""

    env = make_ials(domain.env_id, agent, predictor=predictor, seed=seed, **options)
    try:
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        acts = rng.integers(int(env.action_space.n), size=steps)
        t0 = time.perf_counter()
        for a in acts:
            _, _, terminated, truncated, _ = env.step(int(a))
            if terminated or truncated:
                env.reset()
        return (time.perf_counter() - t0) / steps
    finally:
        env.close()


def ials_batched_seconds(domain: Domain, agent: str, steps: int, seed: int, predictor, n_envs: int,
                          **options) -> float:
    """Seconds per agent-step of ``n_envs`` copies of one agent's IALS stepped together."""

    venv = make_ials_vec_env(domain.env_id, agent, n_envs=n_envs, predictor=predictor, seed=seed, **options)
    try:
        venv.reset()
        rng = np.random.default_rng(seed)
        rounds = max(1, steps // n_envs)
        acts = rng.integers(int(venv.action_space.n), size=(rounds, n_envs))
        t0 = time.perf_counter()
        for a in acts:
            venv.step(a)
        return (time.perf_counter() - t0) / (rounds * n_envs)
    finally:
        venv.close()


def parallel_env_seconds(domain: Domain, steps: int, seed: int, predictors) -> float:
    """Seconds per agent-step of the multi-agent IALS as a PettingZoo ParallelEnv."""

    env = make_ials_parallel_env(domain.env_id, None, predictor=predictors, seed=seed)
    try:
        rng = np.random.default_rng(seed)
        env.reset(seed=seed)
        agents = list(env.possible_agents)
        n = int(env.action_space(agents[0]).n)
        acts = rng.integers(n, size=(steps, len(agents)))
        t0 = time.perf_counter()
        for a in acts:
            if not env.agents:
                env.reset()
            env.step(dict(zip(agents, a.tolist())))
        return (time.perf_counter() - t0) / (steps * len(agents))
    finally:
        env.close()


def multi_agent_seconds(domain: Domain, steps: int, seed: int, predictors, copies: int) -> float:
    """Seconds per agent-step of every agent's IALS x ``copies``, stepped as DIALS does."""

    core = make_multi_agent_ials(domain.env_id, None, copies, predictors, seed=seed)
    try:
        rng = np.random.default_rng(seed)
        core.reset(seed)
        A = len(core.agents)
        n = int(core.ls.action_space.n)
        rounds = max(1, steps // copies)
        acts = rng.integers(n, size=(rounds, A, copies))
        t0 = time.perf_counter()
        for a in acts:
            if core.t >= core.max_cycles:
                core.reset()
            core.step(a)
        return (time.perf_counter() - t0) / (rounds * A * copies)
    finally:
        core.close()


def learner_seconds(domain: Domain, copies: int, seed: int, updates: int = 5,
                     settings: dict | None = None) -> tuple[float, float]:
    """(seconds per agent-step of action selection, per agent-sample of a PPO update) of the
    batched learner of every agent, at the multi-agent baselines' settings (default) or at
    ``settings`` (e.g. :data:`~ials_zoo.baselines.multiagent.PREVIOUS_PPO_SETTINGS`)."""

    agents = domain.agents()
    args = dials.Args(env_id=domain.env_id, **(settings or {}))
    fill_update_size(args, domain)
    cfg = PPOConfig(**ppo_config(args, copies, frame_stack_of(args, domain)))
    width = int(np.prod(domain.observation_space.shape)) * frame_stack_of(args, domain)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        learner = BatchedPPO(agents, width, domain.n_actions, cfg, seed=seed, total_updates=updates + 1)
        rng = np.random.default_rng(seed)
        A, N = len(agents), cfg.n_steps * cfg.n_envs
        obs = rng.random((A, copies, width), dtype=np.float32)
        rounds = max(20, 2000 // (A * copies))
        learner.act(obs)
        t0 = time.perf_counter()
        for _ in range(rounds):
            learner.act(obs)
        act = (time.perf_counter() - t0) / (rounds * A * copies)
        batch = (rng.random((A, N, width), dtype=np.float32), rng.integers(domain.n_actions, size=(A, N)),
                 np.full((A, N), -np.log(domain.n_actions)), rng.standard_normal((A, N)),
                 rng.standard_normal((A, N)), rng.standard_normal((A, N)))
        learner.update(*batch)
        t0 = time.perf_counter()
        for _ in range(updates):
            learner.update(*batch)
        update = (time.perf_counter() - t0) / (updates * A * N)
        return act, update
    finally:
        torch.set_num_threads(threads)


