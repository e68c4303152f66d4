#!/usr/bin/env bash
# MPLight on RESCO's maps (issue 47): one DQN shared by every light on its greens' pressures,
# trained on RESCO's pressure reward, scored on the protocol's (ials_zoo.baselines.mplight);
# budget, evaluations and resuming as studies/resco_maps/learner.sh says.
# Usage: bash studies/resco_maps/mplight.sh "cologne8 grid4x4 ingolstadt21" "0 1 2"
exec bash "$(dirname "$0")/learner.sh" mplight "${1:-cologne8 grid4x4 ingolstadt21}" "${2:-0 1 2}"
