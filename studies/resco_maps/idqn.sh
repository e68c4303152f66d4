#!/usr/bin/env bash
# IDQN on RESCO's maps (issue 47): RESCO's IDQN and its settings (ials_zoo.learners.batched_dqn),
# one GS copy (as RESCO); budget, evaluations and resuming as studies/resco_maps/learner.sh says.
# Usage: bash studies/resco_maps/idqn.sh "cologne8 grid4x4 ingolstadt21" "0 1 2"
exec bash "$(dirname "$0")/learner.sh" idqn "${1:-cologne8 grid4x4 ingolstadt21}" "${2:-0 1 2}"
