#!/usr/bin/env bash
# The meta-RL benchmarks' model and its reward ablation (README.md here), from nothing, on a CPU:
#   docs/results/meta-rl/run.sh [WORK_DIR]      (default work/meta-mujoco; collection and training resume)
# Collects recipe meta-mujoco (400 histories of 500 steps per task, 104 s here), trains config meta-mujoco
# (3,000 steps on 2 threads, about 36 min), evaluates its selected checkpoint cold on env seeds 100-119, 40
# episodes, with true / zero / shuffled / another seed's rewards fed back (about 18 min), and writes the reports.
set -euo pipefail
cd "$(dirname "$0")/../../.."
W=${1:-work/meta-mujoco}
vintix collect --recipe meta-mujoco --out "$W/data" --workers 2
vintix train --config meta-mujoco --data "$W/data" --out "$W/runs/ad" --threads 2
# the evaluations (true, zero, shuffled and another seed's rewards: what each step would have earned under another
# target, the other direction) and the report; collection and training are done
OTHER_GOAL=1 SHOTS=40 scripts/icrl.sh meta-mujoco "$W"
vintix report "$W"/results/ad-{true,zero,shuffled,other-goal} --reference ours --gap-shots 2-10 --out "$W/report-2-10"
# HalfCheetah-Vel: mean x-velocity per half-episode of the selected model, 4 seeds, 4 episodes (the README's table)
python docs/results/meta-rl/vel_speeds.py "$W/runs/ad/checkpoints/best"
