#!/usr/bin/env bash
# DPT on the toy hidden-goal task (point-goal-v1), no search written for it: random-action contexts whose rows record
# the goal-aware expert's action, an MSE head against a flow head, then DAgger rounds (the model's own rollouts,
# relabelled by the expert, joining the data). Each model: cold start on 30 goals no history used (seeds 100-129),
# 10 episodes, true / zero / shuffled rewards fed back. About 25 min on 2 CPU cores.
#   docs/results/dpt/point-goal.sh WORK [ROUNDS]
set -euo pipefail
work=${1:?usage: point-goal.sh WORK [ROUNDS]}
rounds=${2:-2}
vintix=${VINTIX:-vintix}
mkdir -p "$work" && cd "$work"
$vintix collect --recipe point-goal-dpt --out data/random
for head in deterministic flow; do
  data=data/$head
  [ -d "$data" ] || cp -r data/random "$data"
  for round in $(seq 0 "$rounds"); do
    run=runs/$head-round$round
    if [ "$round" -gt 0 ]; then  # DAgger: the last round's model plays 1,000 histories on training goals
      $vintix collect --recipe point-goal-dpt --out "$data" --rollouts-of "runs/$head-round$((round - 1))" \
        --first-history $((1000 * round))
    fi
    $vintix train --config point-goal --data "$data" --set expert_distillation=true \
      --set model_overrides.policy=$head --out "$run" --threads 1
    for reward in true zero shuffled; do
      $vintix eval --checkpoint "$run" --tasks point-goal-v1 --shots 10 --seeds 30 --first-seed 100 \
        --reward-input $reward --out "results/$head-round$round/$reward" --threads 1
    done
  done
done
# Posterior sampling that commits: each flow model again, its noise held for each episode instead of drawn each step.
for round in $(seq 0 "$rounds"); do
  for reward in true zero; do
    $vintix eval --checkpoint "runs/flow-round$round" --tasks point-goal-v1 --shots 10 --seeds 30 --first-seed 100 \
      --reward-input $reward --sample-noise episode --out "results/flow-round$round-episode-noise/$reward" --threads 1
  done
done
