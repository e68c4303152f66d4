"""MPLight: one DQN shared by every light on the GS; see :mod:`ials_zoo.baselines.mplight`.

    python -m baselines.mplight --env sumo_net_v0 --env-options '{"net": "cologne8"}'
"""

import sys

from ials_zoo.baselines import mplight
from ials_zoo.baselines.arguments import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(mplight))
