"""Shared-parameter multi-agent PPO on the GS; see :mod:`ials_zoo.baselines.ppo_shared`.

    python -m baselines.ppo_shared --env warehouse_v0 --total-timesteps 2000000
"""

import sys

from ials_zoo.baselines import ppo_shared
from ials_zoo.baselines.arguments import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(ppo_shared))
