"""PPO baselines (SB3): one agent on a GS or an IALS (:mod:`.ppo_single`), and all agents with
shared parameters on the GS (:mod:`.ppo_shared`).

The implementations live in the installed package so that ``ials-zoo train`` works from any
folder; ``baselines/*.py`` at the repository root are thin runners
(``python -m baselines.ppo_single --help``).
"""

BASELINES = {
    "ppo_single": "ials_zoo.baselines.ppo_single",
    "ppo_shared": "ials_zoo.baselines.ppo_shared",
}
