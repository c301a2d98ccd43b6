#!/usr/bin/env bash
# A hidden-goal task the model never saw (README.md here): icrl-suite's config trained on three of its four Meta-World
# tasks, reach-wall-v3 left out entirely (reach-v3 stays in), on the vintix-cpu collection's histories of them;
# evaluated cold start on 20 unseen reach-wall goals, 20 shots, with true, zero and shuffled rewards fed back,
# and on the three tasks it trained on with true rewards.
#   docs/results/unseen-reach-wall/run.sh DATA [WORK_DIR]
#     DATA: a vintix-cpu collection (`vintix collect --recipe vintix-cpu --out DATA`; scripts/icrl.sh vintix-cpu
#     makes one), WORK_DIR default /tmp/unseen-reach-wall; training resumes.
set -euo pipefail
DATA=$1
W=${2:-/tmp/unseen-reach-wall}
V=${VINTIX:-vintix}
SEEN=reach-v3,push-v3,pick-place-v3
$V train --config icrl-suite --data "$DATA" --out "$W/runs/without-reach-wall" --set "tasks=[$SEEN]" \
  --set "select_tasks=[$SEEN]" --set max_steps=4500 --set select_every=1500
for rewards in true zero shuffled; do
  $V eval --checkpoint "$W/runs/without-reach-wall" --label "without reach-wall ($rewards rewards)" --tasks reach-wall-v3 \
    --shots 20 --seeds 20 --first-seed 100 --reference ours --reward-input "$rewards" --out "$W/results/unseen-$rewards"
done
$V eval --checkpoint "$W/runs/without-reach-wall" --label "without reach-wall, its tasks (true rewards)" --tasks "$SEEN" \
  --shots 20 --seeds 10 --first-seed 100 --reference ours --out "$W/results/seen-true"
$V report "$W"/results/unseen-* --reference ours --out "$W/report"
echo "report: $W/report/report.md"
