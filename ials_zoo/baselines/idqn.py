"""IDQN on the GS: every agent learns its own deep Q-network at once (RESCO's strongest learner).

Usage::

    ials-zoo train idqn --env sumo_net_v0 --env-options '{"net": "cologne8"}'
    python -m baselines.idqn --help

Every agent has its own Q-network, target network, replay buffer and epsilon-greedy
exploration, with RESCO's settings (:mod:`ials_zoo.learners.batched_dqn`: minibatches of 32
from 10,000 transitions, gamma 0.99, Adam, a target update every 500 transitions, epsilon from
1 to 0 over 80% of the run), trained in one batched torch program on ``--n-envs`` copies of
the GS (default 1, as RESCO) with every agent acting. The budget is the domain's multi-agent
one (RESCO's maps: 100 episodes per light, RESCO's IDQN budget).

The policy file holds every agent's Q-network with its outputs divided by
:data:`GREEDY_TEMPERATURE`: its deterministic policy is the argmax of Q (the DQN's own), and
its sampled one the softmax of Q / 0.001, which picks the argmax but for near ties (a DQN at
the end of training acts greedily: epsilon is 0). Outputs in ``--out-dir`` as for :mod:`.ippo`
(``status.json``, ``progress.csv``, ``curve.json``, ``checkpoint.pt``/``.json`` with the
replay buffers, ``policy.safetensors``, ``result.json`` on the multi-agent track); wall-clock:
training only (GS evaluations and checkpoints excluded).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch

from ials_zoo.baselines.arguments import arg, check_frame_stack, hidden_sizes, run_cli
from ials_zoo.baselines.driver import CopiesLearner, check_run_args, gs_run_plan, run
from ials_zoo.baselines.multiagent import JointRunArgs, agent_returns, env_options_of, train_options_of
from ials_zoo.core.domains import domain_ids, get_domain
from ials_zoo.core.extras import study_of
from ials_zoo.core.spaces import joint_sizes
from ials_zoo.errors import BadInput
from ials_zoo.learners.batched_dqn import BatchedDQN, DQNConfig, DQNTrainer, check_dqn_config
from ials_zoo.utils import check_seed

GREEDY_TEMPERATURE = 1e-3
"""The policy file's logits are Q / this (module docstring)."""


@dataclass
class Args(JointRunArgs):
    """Arguments of :func:`main` (``python -m baselines.idqn --help``)."""

    batch_size: int = arg(32, "minibatch of each agent's update (RESCO: 32)")
    gamma: float = arg(0.99, "discount (RESCO: 0.99)")
    learning_rate: float = arg(1e-3, "Adam's learning rate (RESCO: torch's default, 1e-3)")
    buffer_size: int = arg(10_000, "replay buffer of each agent, in transitions (RESCO: 10,000)")
    learning_starts: int = arg(32, "transitions stored before the first update (RESCO: a minibatch)")
    train_every: int = arg(1, "an update every N transitions of each agent (RESCO: 1)")
    target_update: int = arg(500, "the target network copied every N transitions of each agent (RESCO: 500)")
    eps_start: float = arg(1.0, "exploration's epsilon at the start (RESCO: 1)")
    eps_end: float = arg(0.0, "epsilon at the end of its decay (RESCO: 0)")
    eps_fraction: float = arg(0.8, "share of the run over which epsilon falls linearly (RESCO: 0.8)")
    hidden: str = arg("64,64", "hidden layers of every Q-network, comma-separated (RESCO: 64,64)")
    frame_stack: int | None = arg(None, "observations a Q-network reads (default: the domain's)")
    train_reward: str | None = arg(None, "learn from this reward of the domain, in training only (e.g. sumo_net_v0's "
                                   "wait_scaled: wait_norm without its clip); the policy is scored on the protocol's")
    n_envs: int = arg(1, "GS copies (RESCO: 1)")
    gs_processes: int | None = arg(None, "worker processes of the GS copies (default: one per copy for SUMO, else 0)")
    out_dir: str | None = arg(None, "output folder (default: runs/<env>__idqn__s<seed>)")


def dqn_config(args: Args) -> DQNConfig:
    return DQNConfig(batch_size=args.batch_size, gamma=args.gamma, learning_rate=args.learning_rate,
                     buffer_size=args.buffer_size, learning_starts=args.learning_starts,
                     train_every=args.train_every, target_update=args.target_update, eps_start=args.eps_start,
                     eps_end=args.eps_end, eps_fraction=args.eps_fraction, hidden=tuple(hidden_sizes(args.hidden)))


def check_args(args: Args):
    """Clear errors before anything starts; returns (domain, agents, options, worker processes)."""
    if args.env_id is None:
        raise BadInput(f"name the domain to train on: --env, one of {', '.join(domain_ids())}")
    domain = get_domain(args.env_id)
    options = env_options_of(args, domain, only_gs=True)
    agents = domain.check_agents(None if args.agents == "all" else args.agents, **options)
    check_seed(args.seed, "seed")
    hidden_sizes(args.hidden, "hidden")
    check_dqn_config(dqn_config(args))
    check_frame_stack(args.frame_stack)
    check_run_args(args)
    budget, episode = int(args.total_timesteps or study_of(domain).multi_agent_budget), domain.steps_of_episode(**options)
    if budget < max(episode, args.n_envs):
        raise BadInput(f"--total-timesteps {budget:,} is less than one episode ({episode:,} steps of every agent) of "
                       f"the {args.n_envs} GS cop{'ies' if args.n_envs > 1 else 'y'}")
    processes = (args.n_envs if domain.one_simulation_per_process else 0) if args.gs_processes is None else args.gs_processes
    if processes < 0:
        raise BadInput(f"--gs-processes must be >= 0, got {processes}")
    train_options_of(args, domain, options)
    return domain, agents, options, processes



class DQNCopiesLearner(CopiesLearner):
    """The driver's adapter for IDQN: every agent's DQN (:class:`BatchedDQN`) on ``copies`` GS
    copies in ``processes`` worker processes, one step of every copy at a time."""

    activation = "relu"
    log_columns = ("steps_per_agent", "wall_clock_seconds", "mean_episode_return", "loss", "q_mean", "epsilon",
                   "updates")

    def __init__(self, env_id, agents, options, copies, processes, cfg: DQNConfig, frame_stack, seed, total, sizes,
                 learner_cls=BatchedDQN, train_options=None):
        # the GS copies learn under the options plus the learner's own training reward, if any
        self._setup(env_id, agents, {**options, **(train_options or {})}, copies, processes, frame_stack, seed, sizes)
        self.learner = learner_cls(agents, self.obs_size * frame_stack, self.n_actions, cfg, seed, total,
                                   action_counts=self.action_counts)

    def _make_trainer(self):
        return DQNTrainer(self.learner, self.env, self.frame_stack, seed=self.seed)

    def actor_layers(self):
        layers = self.learner.q_layers()
        w, b = layers[-1]
        return layers[:-1] + [(w / GREEDY_TEMPERATURE, b / GREEDY_TEMPERATURE)]

    def train(self, steps, target, advance):
        updates = []
        while steps < target:
            updates += self.trainer.step()
            steps += self.copies
            advance(self.copies)
        returns = self.trainer.episode_returns()
        finite = [] if returns is None else [float(x) for x in returns if x == x]
        row = {"epsilon": self.learner.epsilon(), "updates": self.learner.updates,
               "mean_episode_return": float(np.mean(finite)) if finite else None, "agents": len(self.agents),
               "agent_returns": agent_returns(self.agents, returns)}
        if updates:
            row.update(loss=float(np.mean([u["loss"] for u in updates])),
                       q_mean=float(np.mean([u["q_mean"] for u in updates])))
        return row



def main(args: Args | None = None) -> dict:
    """Train IDQN on the GS; returns the result dict (also written to result.json)."""
    args = args or Args()
    domain, agents, options, processes = check_args(args)
    torch.set_num_threads(1)
    frame_stack = int(args.frame_stack or domain.frame_stack)
    cfg = dqn_config(args)
    per_update = args.n_envs  # one step of every copy: a transition of each agent per copy
    total = int(args.total_timesteps or study_of(domain).multi_agent_budget) // per_update * per_update
    train_options = train_options_of(args, domain, options)
    plan = gs_run_plan("idqn", args, agents, options, total, per_update, frame_stack, processes,
                       {"dqn": dataclasses.asdict(cfg), "greedy_temperature": GREEDY_TEMPERATURE,
                        **({"train_options": train_options} if train_options else {})})
    learner = DQNCopiesLearner(args.env_id, agents, options, args.n_envs, processes, cfg, frame_stack, args.seed,
                               total, joint_sizes(domain, agents, options), train_options=train_options)
    copies = f"{args.n_envs} GS cop{'ies' if args.n_envs > 1 else 'y'}"
    return run(plan, learner, f"idqn: {len(agents)} agents of {args.env_id} learn their own DQN at once on the GS "
               f"({copies}, {processes} worker process{'es' if processes != 1 else ''})", domain)


if __name__ == "__main__":
    import sys

    sys.exit(run_cli(sys.modules[__name__]))
