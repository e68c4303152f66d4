"""PPO for one agent on the GS or an IALS; see :mod:`ials_zoo.baselines.ppo_single`.

    python -m baselines.ppo_single --env warehouse_v0 --simulator ials --total-timesteps 200000
"""

import sys

from ials_zoo.baselines import ppo_single
from ials_zoo.baselines.arguments import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(ppo_single))
