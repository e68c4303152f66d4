"""IDQN: every agent learns its own DQN on the GS; see :mod:`ials_zoo.baselines.idqn`.

    python -m baselines.idqn --env sumo_net_v0 --env-options '{"net": "cologne8"}'
"""

import sys

from ials_zoo.baselines import idqn
from ials_zoo.baselines.arguments import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(idqn))
