#!/usr/bin/env bash
# Put the rules and the learners of RESCO's maps on the board (issue 47 §1): every result file
# named here is submitted, which re-measures it on the GS first (the board's rule); an entry
# already on the board is refused as a duplicate before any episode, so this resumes.
# Usage: bash studies/resco_maps/submit.sh [FILE...]   (default: results/rules/*.json)
set -uo pipefail
cd "$(dirname "$0")/../.."
files=("$@")
[ ${#files[@]} -eq 0 ] && files=(studies/resco_maps/results/rules/*.json)
for f in "${files[@]}"; do
  echo "$(date -u +%H:%M:%S) $f"
  ials-zoo leaderboard submit "$f" 2>&1 | tail -2
done
