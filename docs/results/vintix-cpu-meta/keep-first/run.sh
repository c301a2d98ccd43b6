#!/usr/bin/env bash
# How many of a run's first steps vintix-cpu-meta keeps in its window (../README.md, "Keeping the whole probe"):
# the shipped weights with keep_first_steps K = 100 (as trained), 200, 300 (as shipped), 400, set in a copy of the
# folder's config.json (no weight depends on it), on HalfCheetah-Vel (env seeds 100-119, the evaluation's, and
# 2000-2019, fresh) and the direction tasks (2000-2019; K 100 and 300). 40 episodes each; about 12 min on 1 core.
#   docs/results/vintix-cpu-meta/keep-first/run.sh [WORK_DIR]     (default work/keep-first)
set -euo pipefail
cd "$(dirname "$0")/../../../.."
W=${1:-work/keep-first}
model=$(python -c "from vintix.agent.pretrained import resolve_checkpoint; print(resolve_checkpoint('vintix-cpu-meta'))")
run() { vintix eval --checkpoint "$W/k$1" --tasks "$3" --shots 40 --seeds 20 --first-seed "$2" --reference ours \
          --out "$W/k$1-seeds$2-$4"; }
for k in 100 200 300 400; do
  mkdir -p "$W/k$k" && cp "$model/model.safetensors" "$W/k$k/"
  python -c "import json, sys; c = json.load(open(sys.argv[1])); c['config']['keep_first_steps'] = int(sys.argv[2])
json.dump(c, open(sys.argv[3], 'w'), indent=1)" "$model/config.json" "$k" "$W/k$k/config.json"
  run "$k" 100 HalfCheetah-Vel-v5 vel
  run "$k" 2000 HalfCheetah-Vel-v5 vel
done
for k in 100 300; do run "$k" 2000 HalfCheetah-Dir-v5,Ant-Dir-v5 dir; done
