"""A shard of DIALS: some agents, each learning on its own IALS, in one worker.

A shard holds the multi-agent IALS of its agents (their local simulators and AIPs in one
batch, :class:`~ials_zoo.influence.multi.MultiAgentIALS`) and their learners:

* ``"batched"``: :class:`~ials_zoo.learners.batched_ppo.BatchedPPO`, every agent's PPO in one
  torch program, trained on the shard's multi-agent IALS;
* ``"sb3"``: one stable-baselines3 PPO per agent on its own single-agent IALS vector env (the
  reference learner), trained one agent after the other;
* ``"shared"``: :class:`~ials_zoo.learners.batched_ppo.SharedPPO`, one actor-critic for every
  agent of the shard with its id (``train shared_ppo``'s learner); DIALS keeps such a run to
  one shard, so that the network is every agent's.

Everything an agent does depends on the run seed and its name only (per-agent random
streams, per-agent weights and minibatches), not on which shard holds it: the same seed gives
the same run with any number of workers (:mod:`ials_zoo.learners.batched_ppo` on bitwise
equality); a shared network is the exception, and has one shard.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.utils import LinearSchedule
from stable_baselines3.common.vec_env import VecFrameStack, VecMonitor

from ials_zoo.core.domains import get_domain
from ials_zoo.core.streams import agent_key
from ials_zoo.errors import BadInput
from ials_zoo.influence.ials import make_ials_vec_env
from ials_zoo.influence.multi import make_multi_agent_ials
from ials_zoo.learners.batched_ppo import BatchedPPO, PPOConfig, SharedPPO
from ials_zoo.learners.rollout import IALSVecEnv, RolloutTrainer
from ials_zoo.learners.sb3_state import checkpoint_models, resume_models
from ials_zoo.policy import policy_from_sb3_model, stack_policies
from ials_zoo.runtime.ray_actors import where

LEARNERS = ("batched", "sb3", "shared")
# the learners of every agent in one torch program, by name
PPO_CLASSES = {"batched": BatchedPPO, "shared": SharedPPO}


@dataclass
class ShardSpec:
    """What a worker needs to build its shard (picklable, sent once)."""

    env_id: str
    agents: list
    options: dict
    seed: int
    n_envs: int
    frame_stack: int
    learner: str
    ppo: dict  # PPOConfig fields
    total_updates: int
    predictors: dict = field(default_factory=dict)  # {agent: InfluencePredictor}
    threads: int = 1


class AgentShard:
    """The agents of one worker (module docstring)."""

    def __init__(self, spec: ShardSpec):
        torch.set_num_threads(spec.threads)
        self.spec = spec
        self.domain = get_domain(spec.env_id)
        self.agents = list(spec.agents)
        self.cfg = PPOConfig(**spec.ppo)
        obs_size = int(np.prod(self.domain.observation_space.shape))
        self.input_size = obs_size * spec.frame_stack
        if spec.learner in PPO_CLASSES:
            self._init_batched(spec)
        elif spec.learner == "sb3":
            self._init_sb3(spec)
        else:
            raise BadInput(f"unknown learner {spec.learner!r}; expected one of {LEARNERS}")
        self.steps = 0  # samples per agent so far

    # -- the batched learner on the shard's multi-agent IALS
    def _init_batched(self, spec):
        core = make_multi_agent_ials(spec.env_id, self.agents, spec.n_envs, spec.predictors, seed=spec.seed,
                                     **spec.options)
        self.env = IALSVecEnv(core)
        self.learner = PPO_CLASSES[spec.learner](self.agents, self.input_size, self.domain.n_actions, self.cfg,
                                                 spec.seed, spec.total_updates)
        self.trainer = RolloutTrainer(self.learner, self.env, spec.frame_stack, seed=spec.seed)

    # -- one SB3 PPO per agent (the reference learner)
    def _init_sb3(self, spec):
        cfg = self.cfg
        self.models, self.seeds = {}, {a: (spec.seed * 1_000_003 + agent_key(a)) % 2**31 for a in self.agents}
        for a in self.agents:
            venv = make_ials_vec_env(spec.env_id, a, n_envs=spec.n_envs, predictor=spec.predictors[a],
                                     seed=self.seeds[a], **spec.options)
            wrapped = VecMonitor(venv)
            if spec.frame_stack > 1:
                wrapped = VecFrameStack(wrapped, spec.frame_stack)
            lr = LinearSchedule(cfg.learning_rate, 0.0, 1.0) if cfg.anneal_lr else cfg.learning_rate
            self.models[a] = PPO(
                "MlpPolicy", wrapped, learning_rate=lr, n_steps=cfg.n_steps, batch_size=cfg.batch_size,
                n_epochs=cfg.n_epochs, gamma=cfg.gamma, gae_lambda=cfg.gae_lambda, clip_range=cfg.clip_range,
                ent_coef=cfg.ent_coef, vf_coef=cfg.vf_coef, max_grad_norm=cfg.max_grad_norm,
                seed=self.seeds[a], device="cpu", verbose=0,
                policy_kwargs={"net_arch": {"pi": list(cfg.hidden), "vf": list(cfg.hidden)}})
            self.models[a]._ials_venv = venv
        # the learning rate decays over the whole run (SB3's own schedule would restart at every
        # learn() call, one per DIALS round)
        total = spec.total_updates * cfg.n_steps * spec.n_envs
        for m in self.models.values():
            if cfg.anneal_lr:
                m.lr_schedule = lambda _progress, m=m: cfg.learning_rate * max(0.0, 1.0 - m.num_timesteps / total)

    # -- the worker's commands
    def train(self, until_steps: int) -> dict:
        """Train every agent up to ``until_steps`` samples; returns statistics of this stretch
        (mean episode return per agent, PPO losses)."""
        per_update = self.cfg.n_steps * self.spec.n_envs
        stats: list[dict] = []
        if self.spec.learner in PPO_CLASSES:
            while self.steps + per_update <= until_steps:
                stats.append(self.trainer.collect_and_update())
                self.steps += per_update
            returns = self.trainer.episode_returns()
        else:
            todo = (until_steps - self.steps) // per_update * per_update
            returns = []
            for a in self.agents:
                m = self.models[a]
                if todo > 0:
                    m.learn(todo, reset_num_timesteps=False)
                r = [e["r"] for e in m.ep_info_buffer]
                returns.append(float(np.mean(r)) if r else np.nan)
                m.ep_info_buffer.clear()
            self.steps += todo
            returns = np.array(returns)
        out = {k: float(np.mean([s[k] for s in stats])) for k in (stats[0] if stats else {})}
        out["episode_returns"] = None if returns is None else [float(x) for x in returns]
        out["steps"] = self.steps
        return out

    def set_predictors(self, predictors: dict) -> None:
        """New AIPs for some of the shard's agents (after DIALS retrained them)."""
        mine = {a: p for a, p in predictors.items() if a in self.agents}
        if self.spec.learner in PPO_CLASSES:
            self.env.set_predictors(mine)
            self.trainer.new_episodes()  # an episode runs on one AIP throughout (and replays on it)
        else:
            for a, p in mine.items():
                venv = self.models[a]._ials_venv
                new, old = copy.deepcopy(p), venv.predictor
                new.reset(venv.num_envs)
                # the running episodes keep their histories (as the batched learner's do)
                if getattr(old, "h", None) is not None and getattr(new, "h", None) is not None \
                        and old.h.shape == new.h.shape:
                    new.h = old.h.copy()
                if new.autoregressive and old.autoregressive and new._previous.shape == old._previous.shape:
                    new._previous = old._previous.copy()
                new._t = old._t
                venv.predictor = new

    def where(self) -> tuple[int, str]:
        """This shard's process id and host (so that a backend can watch it)."""

        return where()

    def predictors(self) -> dict:
        """The weights of the AIP each agent's IALS samples from now: ``{agent: {name: array}}``
        (what DIALS's refresh must have replaced)."""
        if self.spec.learner in PPO_CLASSES:
            held = dict(zip(self.env.core.predictor.agents, self.env.core.predictor.predictors))
        else:
            held = {a: self.models[a]._ials_venv.predictor for a in self.agents}
        return {a: {k: np.asarray(v).copy() for k, v in p._arrays().items()} for a, p in held.items()}

    def actor_layers(self) -> list:
        """Every agent's actor weights, stacked: ``[(W [A, in, out], b [A, out]), ...]``."""
        if self.spec.learner in PPO_CLASSES:
            return self.learner.actor_layers()
        nets = [policy_from_sb3_model(self.models[a], a, self.spec.frame_stack) for a in self.agents]
        return stack_policies(nets).layers

    def state(self) -> dict:
        """The learners' state (tensors and plain containers) and the step count: everything
        the shard's future depends on. The SB3 learners' episodes cannot be saved: every
        agent starts new ones here, seeded by its seed and the step count, and
        :meth:`load_state` starts the same ones (:mod:`ials_zoo.learners.sb3_state`)."""
        if self.spec.learner in PPO_CLASSES:
            return {"steps": self.steps, "learner": self.learner.state_dict(), "trainer": self.trainer.state()}
        return dict(checkpoint_models(self.models, self.seeds, self.steps), steps=self.steps)

    def load_state(self, state: dict) -> None:
        self.steps = int(state["steps"])
        if self.spec.learner in PPO_CLASSES:
            self.learner.load_state_dict(state["learner"])
            if "trainer" in state:  # the checkpoint's episodes, replayed to where they were
                self.trainer.restore(state["trainer"])
            return
        if "streams" not in state:
            raise BadInput("this checkpoint was written by an earlier version of ials_zoo, without the state an exact "
                           "resume of SB3 learners needs; start the run again with --overwrite")
        resume_models(self.models, self.seeds, self.steps, state)

    def close(self) -> None:
        if self.spec.learner in PPO_CLASSES:
            self.env.close()
        else:
            for m in self.models.values():
                m.get_env().close()


def split_agents(agents: list, workers: int) -> list[list[str]]:
    """``agents`` in at most ``max(workers, 1)`` contiguous chunks of near-equal size."""
    agents = [str(a) for a in agents]
    n = max(1, min(int(workers), len(agents)))
    bounds = [len(agents) * i // n for i in range(n + 1)]
    return [agents[a:b] for a, b in zip(bounds[:-1], bounds[1:])]


__all__ = ["LEARNERS", "PPO_CLASSES", "AgentShard", "ShardSpec", "split_agents"]
