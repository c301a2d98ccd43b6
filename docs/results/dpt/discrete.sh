#!/usr/bin/env bash
# DPT on the discrete benchmarks, no search written for them: random-action contexts whose rows record the goal-aware
# expert's action (recipes darkroom-dpt, bandit-dpt), trained on that target; Dark Room then one DAgger round (the
# model's own rollouts on training goals, relabelled by the expert, joining the data). Each model: cold start with
# true / zero / shuffled rewards fed back. Dark Room: AD^ε's 16 held-out goals (and 16 seeds of training goals),
# 40 episodes; the bandit: DPT's protocol, 200 bandits no history used, 50 episodes of 10 pulls (500 pulls), regret
# beside UCB1, DPT's UCB and Thompson sampling (scripts/bandit_baselines.py). About 1 h 40 min on 2 CPU cores.
#   docs/results/dpt/discrete.sh WORK
set -euo pipefail
work=${1:?usage: discrete.sh WORK}
here=$(cd "$(dirname "$0")" && pwd)
vintix=${VINTIX:-vintix}
python=${PYTHON:-python}
mkdir -p "$work" && cd "$work"
evaluate() {  # checkpoint, task, shots, seeds, out
  for reward in true zero shuffled; do
    $vintix eval --checkpoint "$1" --tasks "$2" --shots "$3" --seeds "$4" --first-seed 100 --reward-input $reward \
      --out "results/$5/$reward" --threads 1
  done
}
$vintix collect --recipe darkroom-dpt --out data/darkroom-dpt
$vintix train --config darkroom --data data/darkroom-dpt --set expert_distillation=true --out runs/darkroom-dpt --threads 1
evaluate runs/darkroom-dpt DarkRoom-heldout-v0 40 16 darkroom-dpt
$vintix eval --checkpoint runs/darkroom-dpt --tasks DarkRoom-v0 --shots 20 --seeds 16 --first-seed 1000 \
  --out results/darkroom-dpt-train/true --threads 1
$vintix collect --recipe darkroom-dpt --out data/darkroom-dpt --rollouts-of runs/darkroom-dpt --first-history 1000
$vintix train --config darkroom --data data/darkroom-dpt --set expert_distillation=true --out runs/darkroom-dpt-1 \
  --threads 1
evaluate runs/darkroom-dpt-1 DarkRoom-heldout-v0 40 16 darkroom-dpt-1
$vintix collect --recipe bandit-dpt --out data/bandit-dpt
$vintix train --config bandit --data data/bandit-dpt --set expert_distillation=true --out runs/bandit-dpt --threads 1
evaluate runs/bandit-dpt BernoulliBandit-v0 50 200 bandit-dpt
$python "$here/../../../scripts/bandit_baselines.py" --seeds 200 --shots 50 results/bandit-dpt/*
