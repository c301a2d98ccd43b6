#!/usr/bin/env bash
# Meta-World's ML1 meta-test protocol on a shipped model (README.md here): its four hidden-goal Meta-World tasks,
# ML1's 50 test goals each, 10 adaptation + 3 scored episodes, true / zero / shuffled rewards fed back.
#   docs/results/ml1/run.sh [WORK_DIR] [MODEL]      (defaults: ml1, vintix-cpu; vintix-cpu-meta: its own folder here)
set -euo pipefail
cd "$(dirname "$0")/../../.."
W=${1:-ml1}
MODEL=${2:-vintix-cpu}
for rewards in true zero shuffled; do
  vintix eval --checkpoint "$MODEL" --tasks reach-v3,reach-wall-v3,pick-place-v3,push-v3 --ml1 --seeds 50 \
    --reward-input "$rewards" --out "$W/results/$rewards"
done
vintix report "$W/results/true" "$W/results/zero" "$W/results/shuffled" --gap-shots 11-13 --out "$W/report"
