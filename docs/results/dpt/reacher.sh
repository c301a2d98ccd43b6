#!/usr/bin/env bash
# DPT on Reacher-hidden-v5 (MuJoCo's Reacher, its target hidden), no search written for it: random-action contexts
# whose rows record the goal-aware expert's action (recipe reacher-hidden-dpt), a flow head trained on that target
# with icrl-reach's model and settings. Cold start on 20 targets no history used (seeds 100-119), 40 episodes, true /
# zero / shuffled rewards fed back; then one DAgger round (the model's own rollouts, relabelled by the expert, joining
# the data) and the same evaluation. About 2 h on 2 CPU cores.
#   docs/results/dpt/reacher.sh WORK
set -euo pipefail
work=${1:?usage: reacher.sh WORK}
vintix=${VINTIX:-vintix}
mkdir -p "$work" && cd "$work"
$vintix collect --recipe reacher-hidden-dpt --out data/reacher-hidden-dpt
$vintix train --config icrl-reach --data data/reacher-hidden-dpt --set 'select_tasks=[Reacher-hidden-v5]' \
  --set model_overrides.keep_first_steps=0 --set model_overrides.policy=flow --out runs/reacher-hidden-dpt-flow \
  --threads 1
for reward in true zero shuffled; do
  $vintix eval --checkpoint runs/reacher-hidden-dpt-flow --tasks Reacher-hidden-v5 --shots 40 --seeds 20 \
    --first-seed 100 --reward-input $reward --out results/reacher-hidden-dpt-flow/$reward --threads 1
done
# One DAgger round: the model plays 1,000 histories on training targets, the expert relabels them
$vintix collect --recipe reacher-hidden-dpt --out data/reacher-hidden-dpt --rollouts-of runs/reacher-hidden-dpt-flow \
  --first-history 1000
$vintix train --config icrl-reach --data data/reacher-hidden-dpt --set 'select_tasks=[Reacher-hidden-v5]' \
  --set model_overrides.keep_first_steps=0 --set model_overrides.policy=flow --out runs/reacher-hidden-dpt-flow-1 \
  --threads 1
for reward in true zero shuffled; do
  $vintix eval --checkpoint runs/reacher-hidden-dpt-flow-1 --tasks Reacher-hidden-v5 --shots 40 --seeds 20 \
    --first-seed 100 --reward-input $reward --out results/reacher-hidden-dpt-flow-1/$reward --threads 1
done
