"""DIALS: every agent learns at once on its own IALS; see :mod:`ials_zoo.baselines.dials`.

    python -m baselines.dials --env traffic_grid_v0 --total-timesteps 200000
"""

import sys

from ials_zoo.baselines import dials
from ials_zoo.baselines.arguments import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(dials))
