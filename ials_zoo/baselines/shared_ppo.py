"""Shared PPO on the GS: one actor-critic for every agent, each reading its own observation and
its id (the on-policy counterpart of :mod:`.mplight`'s one shared DQN).

Usage::

    ials-zoo train shared_ppo --env sumo_net_v0 --env-options '{"net": "cologne8"}'
    python -m baselines.shared_ppo --help

IPPO's settings, rollouts and outputs (:mod:`.ippo`), with one network
(:class:`ials_zoo.learners.batched_ppo.SharedPPO`): every agent's minibatch goes into one loss
(the mean of theirs) and one gradient clip; an agent's id is a one-hot beside its (zero-padded)
observation, and its greens beyond its own are masked. The policy file holds each agent's actor
(the id folded into the first layer's bias), so it is scored as any joint policy.
"""

from __future__ import annotations

from dataclasses import dataclass

from ials_zoo.baselines import ippo
from ials_zoo.baselines.arguments import arg, run_cli
from ials_zoo.errors import BadInput
from ials_zoo.learners.batched_ppo import SharedPPO

ALGORITHM = "shared_ppo"


@dataclass
class Args(ippo.Args):
    """Arguments of :func:`main` (``python -m baselines.shared_ppo --help``): IPPO's."""

    out_dir: str | None = arg(None, "output folder (default: runs/<env>__shared_ppo__s<seed>)")


def _check_shared(args: Args) -> None:
    if args.recurrent_hidden:
        raise BadInput("--recurrent-hidden: the shared actor-critic reads no GRU (leave it 0)")


def check_args(args: Args):
    """No GRU, and IPPO's checks (:func:`ials_zoo.baselines.ippo.check_args`; what
    ``verify --retrain`` asks of a recorded command)."""
    _check_shared(args)
    return ippo.check_args(args)


def main(args: Args | None = None) -> dict:
    """Train one shared actor-critic for every agent on the GS; returns the result dict."""
    args = args or Args()
    _check_shared(args)  # IPPO's own checks run in ippo.main
    return ippo.main(args, ALGORITHM, SharedPPO)


if __name__ == "__main__":
    import sys

    sys.exit(run_cli(sys.modules[__name__]))
