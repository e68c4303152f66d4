"""Shared-parameter multi-agent PPO on the GS; see :mod:`ials_zoo.baselines.ppo_shared`.

    python -m baselines.ppo_shared --env warehouse_v0 --total-timesteps 2000000
"""

from ials_zoo.baselines.common import parse_args
from ials_zoo.baselines.ppo_shared import Args, main

if __name__ == "__main__":
    import ials_zoo.baselines.ppo_shared as impl

    main(parse_args(Args, description=impl.__doc__.splitlines()[0]))
