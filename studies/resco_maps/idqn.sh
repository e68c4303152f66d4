#!/usr/bin/env bash
# IDQN on RESCO's maps (issue 47): RESCO's IDQN and its settings (ials_zoo.learners.batched_dqn),
# 100 episodes of 360 decisions per light (RESCO's IDQN budget), one GS copy (as RESCO), GS
# evaluations every 20 episodes (5 episodes each; ingolstadt21: every 33 episodes, 3 each) and
# the protocol's 20-episode final score, as studies/resco_maps/ippo.sh does for IPPO. Resumable:
# a finished run is skipped, an interrupted one continues (--resume ends bitwise where the
# uninterrupted run ends).
# Usage: bash studies/resco_maps/idqn.sh "cologne8 grid4x4 ingolstadt21" "0 1 2"
set -euo pipefail
maps=${1:-"cologne8 grid4x4 ingolstadt21"}
seeds=${2:-"0 1 2"}
for seed in $seeds; do
  for net in $maps; do
    out="runs/idqn_net/${net}_s${seed}"
    if [ -f "$out/result.json" ]; then echo "done: $out"; continue; fi
    resume=(); [ -f "$out/checkpoint.json" ] && resume=(--resume)
    evals=(--eval-every 7200 --eval-episodes 5)
    [ "$net" = ingolstadt21 ] && evals=(--eval-every 12000 --eval-episodes 3)
    ials-zoo train idqn --env sumo_net_v0 --env-options "{\"net\": \"$net\"}" --total-timesteps 36000 \
      "${evals[@]}" --seed "$seed" --out-dir "$out" --no-progress "${resume[@]}"
  done
done
