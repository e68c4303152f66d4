#!/usr/bin/env bash
# Shared PPO on RESCO's maps (issue 47): one actor-critic for every light with its id
# (ials_zoo.baselines.shared_ppo), IPPO's settings; budget, evaluations and resuming as
# studies/resco_maps/learner.sh says.
# Usage: bash studies/resco_maps/shared_ppo.sh "cologne8 grid4x4 ingolstadt21" "0 1 2"
exec bash "$(dirname "$0")/learner.sh" shared_ppo "${1:-cologne8 grid4x4 ingolstadt21}" "${2:-0 1 2}"
