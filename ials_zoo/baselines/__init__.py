"""Baselines: PPO for one agent on a GS or an IALS (:mod:`.ppo_single`), all agents with shared
parameters on the GS (:mod:`.ppo_shared`), every agent with its own policy on the GS
(:mod:`.ippo`) or each on its own IALS (:mod:`.dials`), and every agent with its own DQN on the GS
(:mod:`.idqn`, RESCO's IDQN), or one DQN shared by every light on its pressures (:mod:`.mplight`), or one actor-critic
shared by every agent with its id (:mod:`.shared_ppo`).

The implementations live in the installed package so that ``ials-zoo train`` works from any
folder; ``baselines/*.py`` at the repository root are thin runners
(``python -m baselines.ppo_single --help``).
"""

BASELINES = {
    "ppo_single": "ials_zoo.baselines.ppo_single",
    "ppo_shared": "ials_zoo.baselines.ppo_shared",
    "dials": "ials_zoo.baselines.dials",
    "ippo": "ials_zoo.baselines.ippo",
    "idqn": "ials_zoo.baselines.idqn",
    "mplight": "ials_zoo.baselines.mplight",
    "shared_ppo": "ials_zoo.baselines.shared_ppo",
}
