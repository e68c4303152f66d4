"""IPPO on the GS: every agent learns in the one global simulator with its own policy.

Usage::

    ials-zoo train ippo --env traffic_grid_v0 --simulator gs
    python -m baselines.ippo --help

Every agent has its own actor, critic and PPO update (the settings of :mod:`.dials`, one
batched torch program, :mod:`ials_zoo.learners.batched_ppo`); the experience comes from
``--n-envs`` copies of the GS with every agent acting (no scripted agents), which run in
``--gs-processes`` worker processes (default: one per copy for a SUMO GS, none for a numpy
one) while the learner runs here. This is the reference DIALS is compared with: the same
agents, the same PPO, the same budget per agent, trained on the GS instead of on IALS.

Outputs in ``--out-dir`` as for :mod:`.dials` (``status.json``, ``progress.csv``,
``curve.json``, ``checkpoint.pt``/``.json``, ``policy.safetensors``, ``result.json`` on the
multi-agent track); wall-clock: training only (GS evaluations and checkpoints excluded).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ials_zoo.baselines.arguments import arg, run_cli
from ials_zoo.baselines.driver import CopiesLearner, check_run_args, gs_run_plan, run
from ials_zoo.baselines.imitation import imitation_of, warm_start
from ials_zoo.baselines.multiagent import (
    MultiAgentRunArgs,
    check_multi_ppo,
    env_options_of,
    frame_stack_of,
    merge_shard_stats,
    ppo_config,
    train_options_of,
    whole_updates,
)
from ials_zoo.core.domains import domain_ids, get_domain
from ials_zoo.core.extras import study_of
from ials_zoo.core.spaces import joint_sizes
from ials_zoo.errors import BadInput
from ials_zoo.learners.batched_ppo import BatchedPPO, PPOConfig
from ials_zoo.learners.rollout import RolloutTrainer
from ials_zoo.utils import check_seed


@dataclass
class Args(MultiAgentRunArgs):
    """Arguments of :func:`main` (``python -m baselines.ippo --help``)."""

    simulator: str = arg("gs", "gs (IPPO trains on the GS; for IALS use `train dials`)")
    train_reward: str | None = arg(None, "learn from this reward of the domain, in training only (e.g. sumo_net_v0's "
                                   "wait_scaled: wait_norm without its clip); the policy is scored on the protocol's")
    imitate: str | None = arg(None, "warm start: before PPO, fit the actors to this rule of the domain's (e.g. "
                              "greedy, on a SUMO network) over --imitate-episodes GS episodes of its choices "
                              "(ials_zoo.baselines.imitation)")
    imitate_episodes: int | None = arg(None, "GS episodes of the rule's choices that --imitate fits "
                                       "(default: 2; counted as training time)")
    n_envs: int = arg(2, "GS copies")
    gs_processes: int | None = arg(None, "worker processes of the GS copies (default: one per copy for SUMO, else 0)")
    out_dir: str | None = arg(None, "output folder (default: runs/<env>__ippo__s<seed>)")


def check_args(args: Args):
    """Clear errors before anything starts; returns (domain, agents, options, worker processes)."""
    if args.env_id is None:
        raise BadInput(f"name the domain to train on: --env, one of {', '.join(domain_ids())}")
    if args.simulator != "gs":
        raise BadInput(f"ippo trains on the GS (--simulator gs); every agent on its own IALS is `ials-zoo train "
                         f"dials`, not --simulator {args.simulator!r}")
    domain = get_domain(args.env_id)
    # the GS's options, a network of the user's own among them (the board keeps its own maps:
    # such a result is refused by submit, not by training)
    options = env_options_of(args, domain, only_gs=True)
    agents = domain.check_agents(None if args.agents == "all" else args.agents, **options)
    check_seed(args.seed, "seed")
    check_multi_ppo(args, domain)
    check_run_args(args)
    processes = (args.n_envs if domain.one_simulation_per_process else 0) if args.gs_processes is None else args.gs_processes
    if processes < 0:
        raise BadInput(f"gs_processes must be >= 0, got {processes}")
    train_options_of(args, domain, options)
    imitation_of(domain, args.imitate, args.imitate_episodes, frame_stack_of(args, domain), args.recurrent_hidden)
    return domain, agents, options, processes


class GSCopiesLearner(CopiesLearner):
    """The driver's adapter for IPPO: every agent's PPO (:class:`BatchedPPO`) on ``copies``
    GS copies in ``processes`` worker processes, one update of ``samples_per_update`` samples
    of each agent at a time."""

    def __init__(self, env_id, agents, options, copies, processes, ppo, frame_stack, seed, updates, sizes,
                 learner_cls=BatchedPPO, train_options=None, imitation=None, training=None):
        # the GS copies learn under the options plus a training reward of their own, if any
        self._setup(env_id, agents, {**options, **(train_options or {})}, copies, processes, frame_stack, seed, sizes)
        # a warm start from a rule (--imitate), recorded into the run's training record
        self.imitation, self.training, self.imitated = imitation, training, None
        self.per_update = ppo["n_steps"] * ppo["n_envs"]
        self.learner = learner_cls(agents, self.obs_size * frame_stack, self.n_actions, PPOConfig(**ppo), seed,
                                   updates, action_counts=self.action_counts)

    def _make_trainer(self):
        return RolloutTrainer(self.learner, self.env, self.frame_stack, seed=self.seed)

    def actor_layers(self):
        return self.learner.actor_layers()

    def before_training(self, steps, total, policy, note):
        """At the very start, the warm start from a rule (``--imitate``), if asked for."""
        if self.imitation is None or steps > 0 or self.imitated is not None:
            return
        self.imitated = warm_start(self.learner, self.imitation, self.agents, self.options, self.seed, self.obs_size)
        self.training["imitation"] = self.imitated

    def load(self, state, info):
        super().load(state, info)
        if state is not None and state.get("imitation") is not None:
            self.imitated = self.training["imitation"] = state["imitation"]

    def checkpoint(self, out):
        state, info = super().checkpoint(out)
        return dict(state, imitation=self.imitated), info

    def train(self, steps, target, advance):
        stats = []
        while steps < target:
            stats.append(self.trainer.collect_and_update())
            steps += self.per_update
            advance(self.per_update)
        mean = {k: float(np.mean([s[k] for s in stats])) for k in stats[0]}
        returns = self.trainer.episode_returns()
        returns = None if returns is None else [float(x) for x in returns]
        return merge_shard_stats([dict(mean, episode_returns=returns)], [self.agents])



def main(args: Args | None = None, algorithm: str = "ippo", learner_cls=BatchedPPO) -> dict:
    """Train IPPO (or another PPO of every agent at once: ``learner_cls``) on the GS; returns
    the result dict (also written to result.json)."""
    args = args or Args()
    domain, agents, options, processes = check_args(args)
    torch.set_num_threads(1)
    frame_stack = frame_stack_of(args, domain)
    ppo = ppo_config(args, args.n_envs, frame_stack)
    per_update = args.samples_per_update
    total = whole_updates(int(args.total_timesteps or study_of(domain).multi_agent_budget), per_update)
    train_options = train_options_of(args, domain, options)
    extra = {"ppo": ppo, **({"train_options": train_options} if train_options else {})}
    plan = gs_run_plan(algorithm, args, agents, options, total, per_update, frame_stack, processes, extra)
    imitation = imitation_of(domain, args.imitate, args.imitate_episodes, frame_stack, args.recurrent_hidden)
    learner = GSCopiesLearner(args.env_id, agents, options, args.n_envs, processes, ppo, frame_stack, args.seed,
                              total // per_update, joint_sizes(domain, agents, options), learner_cls, train_options,
                              imitation, plan.training)
    copies = f"{args.n_envs} GS cop{'ies' if args.n_envs > 1 else 'y'}"
    return run(plan, learner, f"{algorithm}: {len(agents)} agents of {args.env_id} learn at once on the GS ({copies}, "
               f"{processes} worker process{'es' if processes != 1 else ''})", domain)


if __name__ == "__main__":
    import sys

    sys.exit(run_cli(sys.modules[__name__]))
