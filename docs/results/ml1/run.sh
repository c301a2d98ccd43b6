#!/usr/bin/env bash
# Meta-World's ML1 meta-test protocol on the shipped vintix-cpu (README.md here): its four hidden-goal Meta-World
# tasks, ML1's 50 test goals each, 10 adaptation + 3 scored episodes, true / zero / shuffled rewards fed back.
set -euo pipefail
cd "$(dirname "$0")/../../.."
W=${1:-ml1}
for rewards in true zero shuffled; do
  vintix eval --checkpoint vintix-cpu --tasks reach-v3,reach-wall-v3,pick-place-v3,push-v3 --ml1 --seeds 50 \
    --reward-input "$rewards" --out "$W/results/$rewards"
done
vintix report "$W/results/true" "$W/results/zero" "$W/results/shuffled" --gap-shots 11-13 --out "$W/report"
