#!/usr/bin/env bash
# The rebalanced fine-tune (../README.md, "Rebalanced"), not shipped: recipe vintix-cpu-meta with drawer-close 200
# histories (50 there) and HalfCheetah-Vel 800 (400 there), 4,100 histories (23 min on 2 cores); config
# vintix-cpu-meta started from the shipped vintix-cpu-meta (step 12,000), lr 3e-4, 2,500 steps, selection every 1,250
# (30 min on 2 threads); then drawer-close (seeds 100-109, 10 episodes) and HalfCheetah-Vel (seeds 100-119, 40
# episodes) at each kept checkpoint. Collection and training resume.
#   docs/results/vintix-cpu-meta/rebalanced/run.sh [WORK_DIR]     (default work/vintix-cpu-meta-rebalanced)
set -euo pipefail
cd "$(dirname "$0")/../../../.."
W=${1:-work/vintix-cpu-meta-rebalanced}
mkdir -p "$W"
python -c "import sys, yaml; from vintix.collect.recipe import recipe_path
recipe = yaml.safe_load(recipe_path('vintix-cpu-meta').read_text())
recipe['tasks']['drawer-close-v3'] = {'histories': 200}
recipe['tasks']['HalfCheetah-Vel-v5']['histories'] = 800
yaml.safe_dump(recipe, open(sys.argv[1], 'w'), sort_keys=False)" "$W/recipe.yaml"
vintix collect --recipe "$W/recipe.yaml" --out "$W/data" --workers 2
vintix train --config vintix-cpu-meta --data "$W/data" --out "$W/runs/ad" --threads 2 --set init_from=vintix-cpu-meta \
  --set lr=0.0003 --set max_steps=2500 --set select_every=1250
for step in 1500 2000 2500; do
  checkpoint="$W/runs/ad/checkpoints/step-0000$step"
  vintix eval --checkpoint "$checkpoint" --tasks drawer-close-v3 --shots 10 --seeds 10 --first-seed 100 \
    --reference ours --out "$W/results/step-$step-drawer-close"
  vintix eval --checkpoint "$checkpoint" --tasks HalfCheetah-Vel-v5 --shots 40 --seeds 20 --first-seed 100 \
    --reference ours --out "$W/results/step-$step-vel"
done
