"""IPPO: every agent learns with its own policy on the GS; see :mod:`ials_zoo.baselines.ippo`.

    python -m baselines.ippo --env traffic_grid_v0 --total-timesteps 200000
"""

import sys

from ials_zoo.baselines import ippo
from ials_zoo.baselines.arguments import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(ippo))
