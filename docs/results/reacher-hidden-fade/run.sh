#!/usr/bin/env bash
# Why Reacher-hidden-v5 fades over 40 shots (README.md here): one model per recipe, Reacher-hidden-v5 alone, the
# flagship's config (vintix-cpu) for 2,000 steps; each evaluated cold start on 20 unseen targets, 40 shots,
# with the true and with zero rewards fed back.
#   docs/results/reacher-hidden-fade/run.sh [WORK_DIR]   (default: /tmp/reacher-hidden-fade; every step resumes)
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
W=${1:-/tmp/reacher-hidden-fade}
V=${VINTIX:-vintix}
PYTHON=${PYTHON:-python}
ALONE=(--set 'tasks=[Reacher-hidden-v5]' --set 'select_tasks=[Reacher-hidden-v5]' --set max_steps=2000
       --set select_every=500)
EVAL=(--tasks Reacher-hidden-v5 --shots 40 --seeds 20 --first-seed 100 --reference ours)
for recipe in base tolerant; do
  $V collect --recipe "$HERE/recipe-$recipe.yaml" --out "$W/data-$recipe"
  $V demonstrator histories --task Reacher-hidden-v5 --episodes 10 --seeds 40 --first-seed 1000 \
    $([ $recipe = tolerant ] && echo --reward-tolerance 0.2) > "$W/demonstrator-$recipe.txt"
  $V train --config vintix-cpu --data "$W/data-$recipe" --out "$W/runs/$recipe" "${ALONE[@]}"
  for rewards in true zero; do
    $V eval --checkpoint "$W/runs/$recipe" --label "$recipe ($rewards rewards)" "${EVAL[@]}" --reward-input "$rewards" \
      --out "$W/results/$recipe-$rewards" --overwrite
  done
done
$PYTHON "$HERE/../../../scripts/success_over_shots.py" --strips --drift 0.5 "$W"/results/*-true | tee "$W/success-over-shots.txt"
$V report "$W"/results/* --reference ours --out "$W/report"
echo "report: $W/report/report.md"
