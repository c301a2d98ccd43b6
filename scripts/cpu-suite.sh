#!/usr/bin/env bash
# Rebuild the shipped cpu-suite model and its results from nothing, on a CPU (docs/results.md: "Rebuild the shipped model from nothing").
#   scripts/cpu-suite.sh [WORK_DIR]      (default: cpu-suite/; every step resumes or is skipped once done)
# Steps: collect the suite (AD data) and its expert version (ED data); train AD, ED and AD without
# rewards the same way, each keeping its best checkpoint by cold-start score on unseen seeds/goals;
# evaluate them on the same unseen seeds; write reports normalized by our demonstrators and by the
# paper's table.
set -euo pipefail
W=${1:-cpu-suite}
V=${VINTIX:-vintix}
TRAIN_TASKS=reach-v3,push-v3,button-press-v3,drawer-close-v3,door-open-v3,window-open-v3,industrial-benchmark-10-v1,industrial-benchmark-30-v1,industrial-benchmark-50-v1,industrial-benchmark-70-v1,Reacher-v5,Pusher-v5
TRAIN=(--config tiny --set max_steps=1500 --set warmup_steps=50 --set select_every=150 --set checkpoint_every=150
       --set 'model_overrides={last_reward: false}')  # the paper's token layout, as the shipped model was trained
EVAL=(--shots 20 --first-seed 100 --reference ours)

$V collect --recipe cpu-suite --out "$W/data" --workers 2
$V collect --recipe cpu-suite-expert --out "$W/data-expert" --workers 2
$V train "${TRAIN[@]}" --data "$W/data" --out "$W/runs/ad"
$V train "${TRAIN[@]}" --data "$W/data-expert" --out "$W/runs/ed" --set expert_distillation=true
$V train "${TRAIN[@]}" --data "$W/data" --out "$W/runs/nr" --set 'model_overrides={mask_reward: true, last_reward: false}'

# The same unseen seeds for every model: train tasks for all three (the ablation comparison);
# held-out tasks and physics variations for the shipped AD model.
for model in ad ed nr; do
  $V eval --checkpoint "$W/runs/$model" --label "$model" --tasks "$TRAIN_TASKS" "${EVAL[@]}" --seeds 10 \
    --out "$W/results/$model/train"
done
$V eval --checkpoint "$W/runs/ad" --label ad --tasks test "${EVAL[@]}" --seeds 5 --out "$W/results/ad/held-out"
for variation in viscosity=0.05 viscosity=0.1 gravity_scale=0.9 gravity_scale=1.1; do
  $V eval --checkpoint "$W/runs/ad" --label "ad $variation" --tasks Reacher-v5,Pusher-v5 --variation "$variation" \
    "${EVAL[@]}" --seeds 5 --out "$W/results/ad/${variation/=/-}"
done

for table in ours paper; do
  $V report "$W"/results/{ad,ed,nr}/train --reference "$table" --plateau-shots 10 --out "$W/report/train-$table"
  $V report "$W"/results/ad/held-out --reference "$table" --plateau-shots 10 --out "$W/report/held-out-$table"
  $V report "$W"/results/ad/{viscosity,gravity_scale}-* --reference "$table" --plateau-shots 10 \
    --out "$W/report/physics-$table"
done
echo "models under $W/runs/{ad,ed,nr}/checkpoints/best, results under $W/results, reports under $W/report"
