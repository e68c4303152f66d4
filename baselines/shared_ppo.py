"""Shared PPO: one actor-critic for every agent on the GS; see :mod:`ials_zoo.baselines.shared_ppo`.

    python -m baselines.shared_ppo --env sumo_net_v0 --env-options '{"net": "cologne8"}'
"""

import sys

from ials_zoo.baselines import shared_ppo
from ials_zoo.baselines.arguments import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(shared_ppo))
