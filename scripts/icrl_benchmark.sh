#!/usr/bin/env bash
# One cell of the discrete benchmarks' comparison (docs/discrete-tasks.md): a history source on a task, from nothing.
#   scripts/icrl_benchmark.sh RECIPE CONFIG TASK [WORK_DIR]
#     RECIPE: a recipe of src/vintix/collect/recipes (darkroom-search, darkroom-adeps, darkroom-ad, ...)
#     CONFIG: the training config (darkroom, darkroom-ad, ...); TASK: the held-out task to evaluate on
#     (DarkRoom-heldout-v0, ...); WORK_DIR default: RECIPE-cell/ (collection and training resume where they stopped)
# Collects the recipe's histories, trains CONFIG on them, evaluates the run's selected checkpoint cold on TASK,
# SHOTS episodes (default 40) on SEEDS env seeds from 100 (default 16: each of Dark Room's held-out goals once) with
# true, zero and shuffled rewards fed back, writes the report (its "Reward-use gap" section), and prints the wall
# and CPU time of each stage (times.txt). TRAIN_ARGS: more `vintix train` options (e.g. --threads 2, or --set
# 'select_tasks=[DarkRoomHard-v0]' where the config's selection task is not the recipe's).
set -euo pipefail
RECIPE=${1:?usage: scripts/icrl_benchmark.sh RECIPE CONFIG TASK [WORK_DIR]}
CONFIG=${2:?usage: scripts/icrl_benchmark.sh RECIPE CONFIG TASK [WORK_DIR]}
TASK=${3:?usage: scripts/icrl_benchmark.sh RECIPE CONFIG TASK [WORK_DIR]}
W=${4:-$RECIPE-cell}  # not $RECIPE: a folder here named like the recipe would shadow it
V=${VINTIX:-vintix}
mkdir -p "$W"
# stage NAME COMMAND...: run it, appending its wall seconds and CPU seconds (user + system, its worker processes
# included) to times.txt
stage() {
  local name=$1
  shift
  local TIMEFORMAT="$name: %1R s wall, %1U s user + %1S s system CPU"
  { time "$@" 2>&3; } 3>&2 2>> "$W/times.txt"
  tail -1 "$W/times.txt"
}
stage collect $V collect --recipe "$RECIPE" --out "$W/data"
# shellcheck disable=SC2086  # TRAIN_ARGS is a list of options
stage train $V train --config "$CONFIG" --data "$W/data" --out "$W/run" ${TRAIN_ARGS:-}
for rewards in true zero shuffled; do
  stage "eval $rewards" $V eval --checkpoint "$W/run" --tasks "$TASK" --shots "${SHOTS:-40}" --seeds "${SEEDS:-16}" \
    --first-seed 100 --reward-input "$rewards" --label "$RECIPE" --out "$W/results/$rewards"
done
$V report "$W/results/true" "$W/results/zero" "$W/results/shuffled" --out "$W/report"
