"""Runnable PPO baselines: ``python -m baselines.ppo_single --help``.

Thin runners around :mod:`ials_zoo.baselines` (the implementation lives in the installed
package so that ``ials-zoo train`` works from any folder).
"""
