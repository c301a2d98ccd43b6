#!/usr/bin/env bash
# The flagship fine-tuned to hold the meta-RL tasks (README.md here), on a CPU; collection and training resume where
# they stopped:
#   docs/results/vintix-cpu-meta/run.sh [WORK_DIR]      (default work/vintix-cpu-meta)
# Collects recipe.yaml (3,550 histories, about 25 min on 2 cores), fine-tunes the shipped vintix-cpu on them with
# config.yaml (6,000 steps on 2 threads, about 1 h 45 min with the selections), then evaluates the selected
# checkpoint cold on env seeds 100-119, 40 episodes, on the eight hidden-information tasks with true / zero /
# shuffled / another seed's rewards fed back, and on the visible tasks (10 seeds, 10 episodes, true / zero), and
# writes the reports (scripts/icrl.sh; about 45 min).
set -euo pipefail
cd "$(dirname "$0")/../../.."
D=docs/results/vintix-cpu-meta
W=${1:-work/vintix-cpu-meta}
vintix collect --recipe $D/recipe.yaml --out "$W/data" --workers 2
vintix train --config $D/config.yaml --data "$W/data" --out "$W/runs/ad" --threads 2
RECIPE=$D/recipe.yaml OTHER_GOAL=1 SHOTS=40 scripts/icrl.sh $D/config.yaml "$W"
