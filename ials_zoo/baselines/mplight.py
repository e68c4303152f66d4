"""MPLight on the GS: one DQN shared by every light, reading each green's pressure and learning
from the light's pressure (RESCO's MPLight: ``agents/mplight.py``, ``states.mplight``,
``rewards.pressure``, on our greens).

Usage::

    ials-zoo train mplight --env sumo_net_v0 --env-options '{"net": "cologne8"}'
    python -m baselines.mplight --help

Every light acts with the same Q-network (:class:`ials_zoo.learners.batched_dqn.SharedDQN`:
one replay buffer of 10,000 transitions for all lights, one minibatch of 32 per step of every
light, the target copied every 500 such steps, epsilon from 1 to 0 over 80% of the run: RESCO's
settings, the same as IDQN's), on the domain's pressure observation (a light's greens' pressures
and its current green), trained on its pressure reward (the domain's :class:`LearnerOptions`
``"mplight"``). Two differences from RESCO's, both deliberate:

* the network is a dense MLP over the padded greens, not FRAP (FRAP reads RESCO's hand-written
  phase pairs of each map; any network has greens);
* a time limit bootstraps (as in IDQN).

The policy reads the pressure observation, which its file records (``env_options``); it is
scored, as every policy is, on the board's protocol and the domain's own reward (RESCO's
``wait_norm`` and delay), not on pressure. Outputs and settings as :mod:`.idqn`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch

from ials_zoo.baselines import idqn
from ials_zoo.baselines.arguments import arg, run_cli
from ials_zoo.baselines.driver import gs_run_plan, run
from ials_zoo.core.domains import domain_ids
from ials_zoo.core.extras import learner_options_of, study_of
from ials_zoo.core.spaces import joint_sizes
from ials_zoo.errors import BadInput
from ials_zoo.learners.batched_dqn import SharedDQN

ALGORITHM = "mplight"


@dataclass
class Args(idqn.Args):
    """Arguments of :func:`main` (``python -m baselines.mplight --help``): IDQN's, for the one
    shared DQN (its replay buffer holds every light's transitions)."""

    buffer_size: int = arg(10_000, "replay buffer of the shared DQN, in transitions of all lights (RESCO: 10,000)")
    out_dir: str | None = arg(None, "output folder (default: runs/<env>__mplight__s<seed>)")


def check_args(args: Args):
    """Clear errors before anything starts; returns (domain, agents, options the policy is
    evaluated under, the training's own options, worker processes)."""
    domain, agents, options, processes = idqn.check_args(args)
    mdp = learner_options_of(domain, ALGORITHM)
    if mdp is None:
        having = [d for d in domain_ids() if learner_options_of(d, ALGORITHM) is not None]
        raise BadInput(f"--env: {domain.env_id} has no pressure observation and reward for MPLight; domains that "
                       f"have: {', '.join(having) or 'none'}")
    if args.buffer_size < len(agents):
        raise BadInput(f"--buffer-size ({args.buffer_size}) must hold one step of every light ({len(agents)})")
    if args.train_reward is not None:
        raise BadInput(f"--train-reward: MPLight learns from its own ({mdp.train})")
    clash = sorted(set(options) & (set(mdp.observe) | set(mdp.train)))
    if clash:
        raise BadInput(f"--env-options: MPLight sets {', '.join(clash)} itself ({ {**mdp.observe, **mdp.train} })")
    return domain, agents, {**options, **mdp.observe}, dict(mdp.train), processes


def main(args: Args | None = None) -> dict:
    """Train MPLight on the GS; returns the result dict (also written to result.json)."""
    args = args or Args()
    domain, agents, options, train_options, processes = check_args(args)
    torch.set_num_threads(1)
    frame_stack = int(args.frame_stack or domain.frame_stack)
    cfg = idqn.dqn_config(args)
    per_update = args.n_envs
    total = int(args.total_timesteps or study_of(domain).multi_agent_budget) // per_update * per_update
    plan = gs_run_plan(ALGORITHM, args, agents, options, total, per_update, frame_stack, processes,
                       {"dqn": dataclasses.asdict(cfg), "greedy_temperature": idqn.GREEDY_TEMPERATURE,
                        "shared": True, "train_options": train_options})
    learner = idqn.DQNCopiesLearner(args.env_id, agents, options, args.n_envs, processes, cfg, frame_stack, args.seed,
                                    total, joint_sizes(domain, agents, options), learner_cls=SharedDQN,
                                    train_options=train_options)
    return run(plan, learner, f"mplight: {len(agents)} agents of {args.env_id} share one DQN on the GS, trained on "
               f"{train_options} ({args.n_envs} GS cop{'ies' if args.n_envs > 1 else 'y'})", domain)


if __name__ == "__main__":
    import sys

    sys.exit(run_cli(sys.modules[__name__]))
