#!/usr/bin/env bash
# Rebuild an in-context RL model and its reward-ablation results from nothing, on a CPU.
#   scripts/icrl.sh NAME [WORK_DIR]      NAME: a shipped config and recipe, e.g. icrl-suite, vintix-cpu,
#                                        vintix-cpu-meta (default WORK_DIR: NAME/; collection and training resume
#                                        where they stopped)
# Steps: the histories of recipe NAME (src/vintix/collect/recipes/NAME.yaml: each a hidden goal played
# by a demonstrator that never sees it: it probes the goal box in its first episode, then aims at goals
# drawn from its posterior given the rewards so far); a model trained with config NAME
# (src/vintix/train/configs/NAME.yaml) on the recorded target (the probe, then the goal-aware expert's
# action), checkpoints chosen by cold-start success on unseen goals; cold-start evaluation on 20 unseen
# goals a task (the config's select_tasks, the hidden-goal tasks) with true, zero and shuffled rewards fed
# back, SHOTS episodes each (default 20); the recipe's other tasks (visible ones, vintix-cpu) on 10 unseen
# seeds, 10 shots, with true and zero rewards; the report with the reward-use gap. Set NR=1 to also train and evaluate the AD-without-rewards ablation, ED=1
# the expert-distillation one (the same model trained on the goal-aware expert's histories of the same
# goals, recipe NAME-expert, evaluated with true, zero and shuffled rewards too). Set RECIPE to collect
# another recipe (a name or a YAML file) and train it with config NAME, CHECKPOINT (e.g. step-00009000) to
# evaluate that checkpoint of each run instead of the one its in-context selection kept, OTHER_GOAL=1 to also feed
# the hidden-goal runs what each step would have earned under another seed's goal (`--reward-input other-goal`).
set -euo pipefail
NAME=${1:?usage: scripts/icrl.sh icrl-reach|icrl-suite [WORK_DIR]}
W=${2:-$NAME}
V=${VINTIX:-vintix}
PY=${PYTHON:-python}
config() { $PY -c "import json; from vintix.train.config import load_config; c = load_config('$NAME'); print($1)"; }
TASKS=$(config "','.join(c.select_tasks)")
VISIBLE=$($PY -c "from vintix.collect.recipe import load_recipe; from vintix.train.config import load_config
hidden = set(load_config('$NAME').select_tasks)
print(','.join(p.task for p in load_recipe('${RECIPE:-$NAME}') if p.task not in hidden))")
EVAL=(--tasks "$TASKS" --shots "${SHOTS:-20}" --seeds 20 --first-seed 100 --reference ours)

folders=()
# model RUN: the run's checkpoint to evaluate (a run folder means its selected best)
model() { echo "$W/runs/$1${CHECKPOINT:+/checkpoints/$CHECKPOINT}"; }
# evaluate RUN LABEL REWARDS...: cold-start eval of $W/runs/RUN with each kind of reward fed back
evaluate() {
  local run=$1 label=$2 rewards
  shift 2
  for rewards in "$@"; do
    $V eval --checkpoint "$(model "$run")" --label "$label ($rewards rewards)" "${EVAL[@]}" --reward-input "$rewards" \
      --out "$W/results/$run-$rewards"
    folders+=("$W/results/$run-$rewards")
  done
}

$V collect --recipe "${RECIPE:-$NAME}" --out "$W/data" --workers 2
$V train --config "$NAME" --data "$W/data" --out "$W/runs/ad"
evaluate ad AD true zero shuffled ${OTHER_GOAL:+other-goal}
if [[ -n $VISIBLE ]]; then
  for rewards in true zero; do
    $V eval --checkpoint "$(model ad)" --label "AD, visible tasks ($rewards rewards)" --tasks "$VISIBLE" --shots 10 \
      --seeds 10 --first-seed 100 --reference ours --reward-input "$rewards" --out "$W/results/visible-$rewards"
  done
  $V report "$W/results/visible-true" "$W/results/visible-zero" --reference ours --out "$W/report-visible"
fi
if [[ ${NR:-0} == 1 ]]; then
  $V train --config "$NAME" --data "$W/data" --out "$W/runs/nr" \
    --set "model_overrides=$(config "json.dumps({**c.model_overrides, 'mask_reward': True})")"
  evaluate nr "AD without rewards" true
fi
if [[ ${ED:-0} == 1 ]]; then
  $V collect --recipe "$NAME-expert" --out "$W/data-expert" --workers 2
  $V train --config "$NAME" --data "$W/data-expert" --out "$W/runs/ed"
  evaluate ed ED true zero shuffled
fi
$V report "${folders[@]}" --reference ours --out "$W/report"
echo "model under $(model ad), results under $W/results, report $W/report/report.md"
