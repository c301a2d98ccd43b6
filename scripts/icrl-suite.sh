#!/usr/bin/env bash
# Rebuild the icrl-suite model and its reward-ablation results from nothing, on a CPU.
#   scripts/icrl-suite.sh [WORK_DIR]      (default: icrl-suite/; every step resumes or is skipped once done)
# Steps: the goal-blind table that picks the suite's Meta-World tasks; the suite's histories (a
# demonstrator that infers the hidden goal from rewards, src/vintix/collect/recipes/icrl-suite.yaml);
# training with the goal-aware expert's action as the target, checkpoints chosen by cold-start success
# on unseen goals (the reward-use gap logged beside it); cold-start evaluation on unseen goals/seeds with
# true, zero and shuffled rewards fed back; a report with the reward-use gap.
set -euo pipefail
W=${1:-icrl-suite}
V=${VINTIX:-vintix}
MW=reach-v3,push-v3,pick-place-v3,plate-slide-v3
TASKS=$MW,industrial-benchmark-10-v1,industrial-benchmark-30-v1,industrial-benchmark-50-v1,industrial-benchmark-70-v1,Reacher-v5,Pusher-v5

$V demonstrator goal-blind --task metaworld --seeds 20 --first-seed 100 --out "$W/goal-blind.csv"
$V collect --recipe icrl-suite --out "$W/data" --workers 2
$V train --config icrl-suite --data "$W/data" --out "$W/runs/icrl"   # src/vintix/train/configs/icrl-suite.yaml
for rewards in true zero shuffled; do
  $V eval --checkpoint "$W/runs/icrl" --label icrl-suite --tasks "$TASKS" --shots 20 --seeds 10 --first-seed 100 \
    --reference ours --reward-input "$rewards" --out "$W/results/$rewards"
done
$V report "$W"/results/{true,zero,shuffled} --reference ours --plateau-shots 10 --out "$W/report"
echo "model under $W/runs/icrl/checkpoints/best, results under $W/results, report $W/report/report.md"
