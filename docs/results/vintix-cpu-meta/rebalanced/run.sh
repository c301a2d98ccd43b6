#!/usr/bin/env bash
# The rebalanced fine-tune (../README.md, "Rebalanced"): more drawer-close and HalfCheetah-Vel histories, 2,500 steps
# from the shipped vintix-cpu-meta, then drawer-close (seeds 100-109, 10 episodes) and HalfCheetah-Vel (seeds
# 100-119, 40 episodes) at each kept checkpoint. About 1 h on 2 cores; collection and training resume.
#   docs/results/vintix-cpu-meta/rebalanced/run.sh [WORK_DIR]     (default work/vintix-cpu-meta-rebalanced)
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
cd "$HERE/../../../.."
W=${1:-work/vintix-cpu-meta-rebalanced}
vintix collect --recipe "$HERE/recipe.yaml" --out "$W/data" --workers 2
vintix train --config "$HERE/config.yaml" --data "$W/data" --out "$W/runs/ad" --threads 2
for step in 1500 2000 2500; do
  checkpoint="$W/runs/ad/checkpoints/step-0000$step"
  vintix eval --checkpoint "$checkpoint" --tasks drawer-close-v3 --shots 10 --seeds 10 --first-seed 100 \
    --reference ours --out "$W/results/step-$step-drawer-close"
  vintix eval --checkpoint "$checkpoint" --tasks HalfCheetah-Vel-v5 --shots 40 --seeds 20 --first-seed 100 \
    --reference ours --out "$W/results/step-$step-vel"
done
