#!/usr/bin/env bash
# Rebuild the icrl-reach model and its reward-ablation results from nothing, on a CPU.
#   scripts/icrl-reach.sh [WORK_DIR]      (default: icrl-reach/; collection and training resume where they stopped)
# Steps: 2,000 hidden reach goals, 5 episodes each, played by a demonstrator that never sees the goal
# (it probes the goal box in its first episode, then aims at goals drawn from its posterior given the rewards
# so far; src/vintix/collect/recipes/icrl-reach.yaml); a model trained on its recorded target (the probe,
# then the goal-aware expert's action), checkpoints chosen by
# cold-start success on unseen goals (src/vintix/train/configs/icrl-reach.yaml); cold-start
# evaluation on 20 unseen goals with true, zero and shuffled rewards fed back; the report with the
# reward-use gap. Set NR=1 to also train and evaluate the AD-without-rewards ablation, ED=1 the
# expert-distillation one (the same model trained on the goal-aware expert's histories of the same
# goals, evaluated with true, zero and shuffled rewards too).
set -euo pipefail
W=${1:-icrl-reach}
V=${VINTIX:-vintix}
EVAL=(--tasks reach-v3 --shots 20 --seeds 20 --first-seed 100 --reference ours)

folders=()
# evaluate RUN LABEL REWARDS...: cold-start eval of $W/runs/RUN with each kind of reward fed back
evaluate() {
  local run=$1 label=$2 rewards
  shift 2
  for rewards in "$@"; do
    $V eval --checkpoint "$W/runs/$run" --label "$label ($rewards rewards)" "${EVAL[@]}" --reward-input "$rewards" \
      --out "$W/results/$run-$rewards"
    folders+=("$W/results/$run-$rewards")
  done
}

$V collect --recipe icrl-reach --out "$W/data" --workers 2
$V train --config icrl-reach --data "$W/data" --out "$W/runs/ad"
evaluate ad AD true zero shuffled
if [[ ${NR:-0} == 1 ]]; then
  $V train --config icrl-reach --data "$W/data" --out "$W/runs/nr" --set 'model_overrides={reward_encoder: mlp, rew_emb_dim: 16, obs_emb_dim: 56, act_emb_dim: 56, context_len: 500, keep_first_steps: 100, mask_reward: true}'
  evaluate nr "AD without rewards" true
fi
if [[ ${ED:-0} == 1 ]]; then
  $V collect --recipe icrl-reach-expert --out "$W/data-expert" --workers 2
  $V train --config icrl-reach --data "$W/data-expert" --out "$W/runs/ed"
  evaluate ed ED true zero shuffled
fi
$V report "${folders[@]}" --reference ours --out "$W/report"
echo "model under $W/runs/ad/checkpoints/best, results under $W/results, report $W/report/report.md"
