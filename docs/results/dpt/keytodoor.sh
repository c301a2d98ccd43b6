#!/usr/bin/env bash
# Key-to-Door with AD^eps's random start (KeyToDoorRandomStart-v0): the shipped keytodoor's walk search and DPT's
# target (random moves, the goal-aware expert's move recorded) on the same 4,000 training-pair histories of 800 steps,
# each trained with the keytodoor-walk config (1,500 steps), then cold start on the 16 held-out pairs of env seeds
# 100-115, 40 episodes, with true / zero / shuffled rewards fed back; then one DAgger round for DPT. About 1 h 45 min
# on 2 CPU cores, one job at a time.
#   docs/results/dpt/keytodoor.sh WORK
set -euo pipefail
work=${1:?usage: keytodoor.sh WORK}
here=$(cd "$(dirname "$0")" && pwd)
vintix=${VINTIX:-vintix}
mkdir -p "$work" && cd "$work"
for source in walk dpt; do
  $vintix collect --recipe "$here/keytodoor-randomstart-$source.yaml" --out "data/$source" --threads 1
  $vintix train --config keytodoor-walk --data "data/$source" --out "runs/$source" --threads 1
  for reward in true zero shuffled; do
    $vintix eval --checkpoint "runs/$source" --tasks KeyToDoorRandomStart-heldout-v0 --shots 40 --seeds 16 \
      --first-seed 100 --reward-input $reward --out "results/$source/$reward" --threads 1
  done
  $vintix report results/$source/{true,zero,shuffled} --out "reports/keytodoor-randomstart-$source"
done
# One DAgger round for DPT: the model's own rollouts on the training pairs, relabelled by the expert, then afresh.
$vintix collect --recipe "$here/keytodoor-randomstart-dpt.yaml" --out data/dpt --rollouts-of runs/dpt --first-history 4000
$vintix train --config keytodoor-walk --data data/dpt --out runs/dpt-1 --threads 1
for reward in true zero shuffled; do
  $vintix eval --checkpoint runs/dpt-1 --tasks KeyToDoorRandomStart-heldout-v0 --shots 40 --seeds 16 --first-seed 100 \
    --reward-input $reward --out "results/dpt-1/$reward" --threads 1
done
$vintix report results/dpt-1/{true,zero,shuffled} --out reports/keytodoor-randomstart-dpt-1
