#!/usr/bin/env bash
# A meta-RL task the model never saw (README.md here): config meta-mujoco trained on HalfCheetah-Vel and Ant-Dir
# only, HalfCheetah-Dir left out (its body's group is HalfCheetah-Vel's, so the model has an encoder and head for
# it, with normalization pooled over the group); evaluated cold on HalfCheetah-Dir, env seeds 100-119, 40
# episodes, with true / zero / the other direction's rewards fed back, and on its own two tasks with true rewards
# (10 seeds, 10 episodes).
#   docs/results/meta-rl/held-out-cheetah-dir/run.sh [WORK_DIR]   (default work/held-out-cheetah-dir; resumes)
# Collection about 2 min (recipe meta-mujoco, HalfCheetah-Dir's histories are collected and not trained on),
# training about 40 min on 2 threads, evaluations about 4 min.
set -euo pipefail
cd "$(dirname "$0")/../../../.."
W=${1:-work/held-out-cheetah-dir}
SEEN=HalfCheetah-Vel-v5,Ant-Dir-v5
vintix collect --recipe meta-mujoco --out "$W/data" --workers 2
vintix train --config meta-mujoco --data "$W/data" --out "$W/runs/without-cheetah-dir" --threads 2 \
  --set "tasks=[$SEEN]" --set "select_tasks=[$SEEN]"
for rewards in true zero other-goal; do
  vintix eval --checkpoint "$W/runs/without-cheetah-dir" --label "without HalfCheetah-Dir ($rewards rewards)" \
    --tasks HalfCheetah-Dir-v5 --shots 40 --seeds 20 --first-seed 100 --reference ours --reward-input "$rewards" \
    --out "$W/results/unseen-$rewards"
done
vintix eval --checkpoint "$W/runs/without-cheetah-dir" --label "without HalfCheetah-Dir, its tasks (true rewards)" \
  --tasks "$SEEN" --shots 10 --seeds 10 --first-seed 100 --reference ours --out "$W/results/seen-true"
vintix report "$W"/results/unseen-* --reference ours --out "$W/report"
echo "report: $W/report/report.md"
