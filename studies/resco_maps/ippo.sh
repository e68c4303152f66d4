#!/usr/bin/env bash
# IPPO on RESCO's maps (docs/sumo_net.md): the zoo's multi-agent PPO, 2 GS copies in 2 worker
# processes; budget, evaluations and resuming as studies/resco_maps/learner.sh says.
# Usage: bash studies/resco_maps/ippo.sh "cologne8 grid4x4 ingolstadt21" "0 1 2"
exec bash "$(dirname "$0")/learner.sh" ippo "${1:-cologne8 grid4x4 ingolstadt21}" "${2:-0 1 2}"
