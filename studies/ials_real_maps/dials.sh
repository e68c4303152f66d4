#!/usr/bin/env bash
# DIALS on RESCO's maps (docs/sumo_net.md) at IPPO's budget and evaluations (studies/resco_maps/ippo.sh):
# 100 episodes of 360 decisions per light, 2 IALS copies (every light's region in one SUMO simulation
# each) in 2 worker processes, the AIPs trained on 720 GS decisions of the joint policy at 0, 12,000
# and 24,000 steps per light; GS evaluations as IPPO's, the protocol's 20-episode final score.
# variant "untrained": untrained-DIALS (random AIPs, never trained), the control; variant "fidelity":
# the AIPs of `ials-zoo fidelity` (autoregressive, reading their own last draw: --aip-training fidelity);
# variant "shared": trained AIPs, and shared PPO's one network for every light (--learner shared).
# Resumable: a finished run is skipped, an interrupted one continues with --resume.
# A fifth argument retrains the AIPs every N steps per light instead of 12,000 (its runs get "_rN").
# Usage: bash studies/ials_real_maps/dials.sh "ingolstadt21 cologne8" "0 1 2" [trained|untrained|fidelity|shared] [runs folder] [N]
set -euo pipefail
maps=${1:-"ingolstadt21 cologne8"}
seeds=${2:-"0 1 2"}
variant=${3:-trained}
root=${4:-runs/dials_net}
refresh=${5:-12000}
case "$variant" in trained|untrained|fidelity|shared) ;; *) echo "variant must be trained, untrained, fidelity or shared, got '$variant'" >&2; exit 2;; esac
for seed in $seeds; do
  for net in $maps; do
    aips=(--refresh "$refresh")
    tag=""; if [ "$refresh" != 12000 ]; then tag="_r$refresh"; fi
    if [ "$variant" = untrained ]; then aips=(--aip untrained --refresh never); tag="_untrained"; fi
    if [ "$variant" = fidelity ]; then aips+=(--aip-training fidelity); tag="_fidelity$tag"; fi
    if [ "$variant" = shared ]; then aips+=(--learner shared); tag="_shared$tag"; fi
    out="$root/${net}${tag}_s${seed}"
    if [ -f "$out/result.json" ]; then echo "done: $out"; continue; fi
    resume=(); [ -f "$out/checkpoint.json" ] && resume=(--resume)
    evals=(--eval-every 7200 --eval-episodes 5)
    [ "$net" = ingolstadt21 ] && evals=(--eval-every 12000 --eval-episodes 3)
    ials-zoo train dials --env sumo_net_v0 --env-options "{\"net\": \"$net\"}" --total-timesteps 36000 \
      "${aips[@]}" "${evals[@]}" --seed "$seed" --out-dir "$out" --no-progress "${resume[@]}"
  done
done
