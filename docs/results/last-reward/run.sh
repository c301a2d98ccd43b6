#!/usr/bin/env bash
# The last-reward measurement (README.md here): one dataset, two models (the tiny preset's last_reward, and the paper's
# token layout), each evaluated on 30 unseen targets with the true and with zero rewards fed back.
#   docs/results/last-reward/run.sh [WORK_DIR]       (default: /tmp/last-reward; collection and training resume)
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
W=${1:-/tmp/last-reward}
V=${VINTIX:-vintix}
export PYTHONPATH="$HERE${PYTHONPATH:+:$PYTHONPATH}" VINTIX_TASKS="$HERE/tasks.yaml"
PAPER_LAYOUT='model_overrides={reward_encoder: mlp, rew_emb_dim: 16, obs_emb_dim: 24, act_emb_dim: 24, n_layers: 2,
  n_heads: 2, mlp_dim: 256, last_reward: false}'
EVAL=(--tasks terminal-target --shots 4 --seeds 30 --first-seed 100 --reference ours)
$V collect --recipe "$HERE/recipe.yaml" --out "$W/data"
$V train --config "$HERE/train.yaml" --data "$W/data" --out "$W/runs/last-reward"
$V train --config "$HERE/train.yaml" --data "$W/data" --out "$W/runs/paper-layout" --set "$PAPER_LAYOUT"
folders=()
for run in last-reward paper-layout; do
  for rewards in true zero; do
    $V eval --checkpoint "$W/runs/$run" --label "$run ($rewards rewards)" "${EVAL[@]}" --reward-input "$rewards" \
      --out "$W/results/$run-$rewards"
    folders+=("$W/results/$run-$rewards")
  done
done
$V report "${folders[@]}" --plateau-shots 3 --reference ours --out "$W/report"
echo "report: $W/report/report.md"
