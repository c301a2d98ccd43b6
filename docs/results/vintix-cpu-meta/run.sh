#!/usr/bin/env bash
# vintix-cpu-meta, the flagship fine-tuned to hold the meta-RL tasks (README.md here; the shipped model's
# TRAINING.md), on a CPU; collection and training resume where they stopped:
#   docs/results/vintix-cpu-meta/run.sh [WORK_DIR]      (default work/vintix-cpu-meta)
# Collects recipe vintix-cpu-meta (3,550 histories, about 20 min on 2 cores), fine-tunes the shipped vintix-cpu on
# them with config vintix-cpu-meta for 6,000 steps, then resumes to 9,000 and 12,000 (each resume recomputes the
# cosine schedule; about 2 h 45 min on 2 threads in all), then evaluates step 12,000 cold on env seeds 100-119, 40
# episodes, on the eight hidden-information tasks with true / zero / shuffled / another seed's rewards fed back, and
# on the visible tasks (10 seeds, 10 episodes, true / zero), writes the reports (scripts/icrl.sh; about 35 min), and
# runs Meta-World's ML1 protocol on the shipped model (docs/results/ml1/run.sh; about 20 min). The config keeps a
# run's first 300 steps in the agent's window (keep_first_steps, no weight depends on it): the shipped model's run
# kept 100 and was set to 300 after keep-first/run.sh's sweep, so its in-context selection scored with 100.
# Then what this folder records without keeping the files: the checkpoints of steps 6,000 and 9,000 (step-*/model,
# window 100) and the evaluations of steps 6,000, 9,000, 12,000 (window 100) and 15,000 (a resume; the
# episodes.csv of each), each into WORK/step-STEP/ as named here; about 2 h more.
set -euo pipefail
cd "$(dirname "$0")/../../.."
W=${1:-work/vintix-cpu-meta}
train() { vintix train --config vintix-cpu-meta --data "$W/data" --out "$W/runs/ad" --threads 2 "$@"; }
# keep STEP: that step's checkpoint copied to WORK/step-STEP/model (weights and config, no optimizer state) before
# later checkpoints prune it, with the window the run was trained and selected with (keep_first_steps 100)
keep() {
  local from=$W/runs/ad/checkpoints/step-$(printf %08d "$1") to=$W/step-$1/model
  mkdir -p "$to" && cp "$from/model.safetensors" "$to/"
  python -c "import json, sys; c = json.load(open(sys.argv[1])); c['config']['keep_first_steps'] = 100
json.dump(c, open(sys.argv[2], 'w'), indent=1)" "$from/config.json" "$to/config.json"
}
vintix collect --recipe vintix-cpu-meta --out "$W/data" --workers 2
train
keep 6000
train --set max_steps=9000 --set select_every=3000
keep 9000
train --set max_steps=12000 --set select_every=3000
keep 12000
# the shipped model: step 12,000 with keep_first_steps 300 (this folder's step-12000-keep300/: WORK/results,
# WORK/report, WORK/report-visible)
CHECKPOINT=step-00012000 OTHER_GOAL=1 SHOTS=40 scripts/icrl.sh vintix-cpu-meta "$W"
docs/results/ml1/run.sh "$W/ml1" vintix-cpu-meta

# The records beside it (README.md here), window 100, into WORK/step-STEP/ as this folder names them.
HIDDEN=reach-v3,push-v3,pick-place-v3,reach-wall-v3,Reacher-hidden-v5,HalfCheetah-Vel-v5,HalfCheetah-Dir-v5,Ant-Dir-v5
VISIBLE=Reacher-v5,Pusher-v5,industrial-benchmark-30-v1,industrial-benchmark-70-v1,button-press-v3,drawer-close-v3
VISIBLE=$VISIBLE,window-open-v3
META=HalfCheetah-Vel-v5,HalfCheetah-Dir-v5,Ant-Dir-v5
# full STEP: what scripts/icrl.sh evaluates (steps 6,000 and 12,000)
full() {
  local model=$W/step-$1/model out=$W/step-$1 r
  for r in true zero shuffled other-goal; do
    vintix eval --checkpoint "$model" --label "AD ($r rewards)" --tasks "$HIDDEN" --shots 40 --seeds 20 \
      --first-seed 100 --reference ours --reward-input "$r" --out "$out/results/ad-$r"
  done
  for r in true zero; do
    vintix eval --checkpoint "$model" --label "AD, visible tasks ($r rewards)" --tasks "$VISIBLE" --shots 10 \
      --seeds 10 --first-seed 100 --reference ours --reward-input "$r" --out "$out/results/visible-$r"
  done
  vintix report "$out"/results/ad-{true,zero,shuffled,other-goal} --reference ours --out "$out/report"
  vintix report "$out"/results/visible-{true,zero} --reference ours --out "$out/report-visible"
}
# meta STEP DRAWER: the three meta-RL tasks with true and zero rewards, and drawer-close (steps 9,000 and 15,000)
meta() {
  local model=$W/step-$1/model out=$W/step-$1 r
  for r in true zero; do
    vintix eval --checkpoint "$model" --label "step $1 ($r rewards)" --tasks "$META" --shots 40 --seeds 20 \
      --first-seed 100 --reference ours --reward-input "$r" --out "$out/results/$r"
  done
  vintix eval --checkpoint "$model" --tasks drawer-close-v3 --shots 10 --seeds 10 --first-seed 100 --reference ours \
    --out "$out/results/$2"
}
full 6000
meta 9000 visible-drawer-close
full 12000
# resumed once more, to step 15,000 (not shipped; the run's best stays step 12,000)
train --set max_steps=15000 --set select_every=3000
keep 15000
meta 15000 drawer-close
