"""PPO for one agent on the GS or an IALS; see :mod:`ials_zoo.baselines.ppo_single`.

    python -m baselines.ppo_single --env warehouse_v0 --simulator ials --total-timesteps 200000
"""

from ials_zoo.baselines.common import parse_args
from ials_zoo.baselines.ppo_single import Args, main

if __name__ == "__main__":
    import ials_zoo.baselines.ppo_single as impl

    main(parse_args(Args, description=impl.__doc__.splitlines()[0]))
