#!/usr/bin/env bash
# The rules on the board's protocol (issue 47 §1): every map's rules (fixed, greedy, max_pressure,
# actuated: `ials-zoo evaluate --joint --policy rule:NAME`) and random, 20 episodes each (seeds
# 10000-10019), one result file per map and rule under studies/resco_maps/results/rules/. Resumes:
# a finished file is kept. Submit them with `ials-zoo leaderboard submit FILE` (it re-measures).
# Usage: bash studies/resco_maps/rules.sh "cologne8 grid4x4 ingolstadt21" "fixed greedy max_pressure actuated random"
set -euo pipefail
maps="${1:-cologne8 grid4x4 ingolstadt21 cologne1 ingolstadt1 ingolstadt7 cologne3 arterial4x4}"
rules="${2:-fixed greedy max_pressure actuated random}"
out="$(dirname "$0")/results/rules"
mkdir -p "$out"
for m in $maps; do
  for r in $rules; do
    f="$out/${m}_${r}.json"
    [ -f "$f" ] && continue
    policy="rule:$r"; [ "$r" = random ] && policy=random
    echo "$(date -u +%H:%M:%S) $m $r"
    ials-zoo evaluate --env sumo_net_v0 --env-options "{\"net\": \"$m\"}" --joint --policy "$policy" \
      --out "$f" --no-progress --notes "studies/resco_maps/rules.sh at $(git rev-parse --short HEAD)"
  done
done
