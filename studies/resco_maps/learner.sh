#!/usr/bin/env bash
# A learner of ials-zoo on RESCO's maps (docs/sumo_net.md), as studies/resco_maps/ippo.sh and
# idqn.sh run it: 100 episodes of 360 decisions per light (RESCO's IDQN budget), GS evaluations
# every 20 episodes (5 episodes each; ingolstadt21, whose episodes cost ten times more: every 33
# episodes, 3 each), the protocol's 20-episode final score. Resumable: a finished run is skipped,
# an interrupted one continues (--resume ends bitwise where the uninterrupted run ends).
# Usage: bash studies/resco_maps/learner.sh LEARNER "cologne8 grid4x4 ingolstadt21" "0 1 2" [extra flags...]
# OBSERVATION=wave: the lights read that observation (a policy option of the board's track); the
# runs go to runs/LEARNER_OBSERVATION_net. RUN_TAG=T (with extra flags): runs/LEARNER[_OBSERVATION]_T_net.
set -euo pipefail
learner=$1
maps=${2:-"cologne8 grid4x4 ingolstadt21"}
seeds=${3:-"0 1 2"}
shift $(( $# < 3 ? $# : 3 ))
for seed in $seeds; do
  for net in $maps; do
    out="runs/${learner}${OBSERVATION:+_$OBSERVATION}${RUN_TAG:+_$RUN_TAG}_net/${net}_s${seed}"
    if [ -f "$out/result.json" ]; then echo "done: $out"; continue; fi
    resume=(); [ -f "$out/checkpoint.json" ] && resume=(--resume)
    evals=(--eval-every 7200 --eval-episodes 5)
    [ "$net" = ingolstadt21 ] && evals=(--eval-every 12000 --eval-episodes 3)
    ials-zoo train "$learner" --env sumo_net_v0 --env-options "{\"net\": \"$net\"${OBSERVATION:+, \"observation\": \"$OBSERVATION\"}}" --total-timesteps 36000 \
      "${evals[@]}" --seed "$seed" --out-dir "$out" --no-progress "${resume[@]}" "$@"
  done
done
