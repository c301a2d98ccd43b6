#!/usr/bin/env bash
# The corridor newcomer's task (corridor.py), sized by docs/training.md's rule at the first try: collect the search's
# histories, train once, and evaluate 30 episodes from an empty context on held-out treasures (a region no training
# treasure was in: cells 5-6) with true and zero rewards fed back, and on training cells with new seeds. The training
# prints its own cost forecast after its first steps; this script times the whole. About 30 min on 2 CPU cores.
#   docs/results/corridor/run.sh WORK
set -euo pipefail
work=${1:?usage: run.sh WORK}
here=$(cd "$(dirname "$0")" && pwd)
vintix=${VINTIX:-vintix}
mkdir -p "$work" && cd "$work"
cp "$here/corridor.py" "$here/tasks.yaml" "$here/recipe.yaml" "$here/train.yaml" .
export VINTIX_TASKS=tasks.yaml PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH}
$vintix collect --recipe recipe.yaml --out data
start=$(date +%s)
$vintix train --config train.yaml --data data --out run --threads 1 | tee train.log
echo "training took $(( ($(date +%s) - start) / 60 )) min $(( ($(date +%s) - start) % 60 )) s" | tee -a train.log
for reward in true zero; do
  $vintix eval --checkpoint run --tasks corridor-heldout --shots 30 --seeds 20 --first-seed 100 --reward-input $reward \
    --out results/heldout-$reward --threads 1
done
$vintix eval --checkpoint run --tasks corridor --shots 30 --seeds 20 --first-seed 100 --out results/train-true --threads 1
$vintix report results/heldout-true results/heldout-zero --reference ours --out report
