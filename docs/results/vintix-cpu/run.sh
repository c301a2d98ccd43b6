#!/usr/bin/env bash
# vintix-cpu, the cross-domain flagship (README.md here), from nothing on a CPU, with every evaluation whose raw
# per-episode files (episodes.csv) this folder no longer keeps; collection and training resume where they stopped.
#   docs/results/vintix-cpu/run.sh WORK
# Training about 2 h on 2 threads; each 40-shot evaluation 15-30 min on one thread. WORK then holds what this folder
# holds, under the same names:
#   step-7500/results/ad-true    the checkpoint the in-context selection kept (step 7,500), on the reported goals
#   validation/{best,step-00009000}  steps 7,500 and 9,000 on Reacher-hidden targets of seeds 200-219 (the tie-break;
#                                here validation/step-7500 and validation/step-9000)
#   results/, report/, report-visible/   step 9,000, the shipped checkpoint (true / zero / shuffled rewards, 40 shots;
#                                visible tasks true / zero, 10 shots)
#   first-run/                   the first run: the recipe of commit 8760f98 (Reacher-hidden without
#                                reward_tolerance: 0.2), the same config; its results/, report*/ and the icrl-suite
#                                comparison (results/icrl-suite-true, report-between/)
#   report-between/, report-first-run/   step 9,000 against icrl-suite and against the first run
set -euo pipefail
W=${1:?usage: docs/results/vintix-cpu/run.sh WORK}
mkdir -p "$W"
W=$(cd "$W" && pwd)
cd "$(dirname "$0")/../../.."
V=${VINTIX:-vintix}
export VINTIX=$V PYTHON=${PYTHON:-python}

# The run; its in-context selection keeps step 7,500, evaluated first (true / zero / shuffled, visible tasks).
SHOTS=40 scripts/icrl.sh vintix-cpu "$W"
if [[ ! -d $W/step-7500 ]]; then
  mkdir -p "$W/step-7500"
  mv "$W/results" "$W/report" "$W/report-visible" "$W/step-7500/"
fi
# The selection had saturated at 1.00: steps 7,500 (best) and 9,000 on targets neither training nor the results use.
for c in best step-00009000; do
  $V eval --checkpoint "$W/runs/ad/checkpoints/$c" --tasks Reacher-hidden-v5 --shots 20 --seeds 20 \
    --first-seed 200 --reference ours --out "$W/validation/$c"
done
# Step 9,000 ships: the same evaluations of it.
CHECKPOINT=step-00009000 SHOTS=40 scripts/icrl.sh vintix-cpu "$W"

# The first run (faded on Reacher-hidden over 40 shots): the recipe as it was at commit 8760f98.
mkdir -p "$W/first-run"
git show 8760f98:src/vintix/collect/recipes/vintix-cpu.yaml > "$W/first-run/recipe.yaml"
RECIPE="$W/first-run/recipe.yaml" SHOTS=40 scripts/icrl.sh vintix-cpu "$W/first-run"
$V eval --checkpoint icrl-suite --tasks reach-v3,push-v3,pick-place-v3,reach-wall-v3 --shots 40 --seeds 20 \
  --first-seed 100 --reference ours --label "icrl-suite (true rewards)" --out "$W/first-run/results/icrl-suite-true"
$V report "$W/first-run/results/ad-true" "$W/first-run/results/icrl-suite-true" --reference ours \
  --out "$W/first-run/report-between"

# Step 9,000 against icrl-suite and against the first run, on the same goals.
$V report "$W/results/ad-true" "$W/first-run/results/icrl-suite-true" --reference ours --out "$W/report-between"
$V report "$W/results/ad-true" "$W/first-run/results/ad-true" --reference ours --out "$W/report-first-run"
$PYTHON scripts/success_over_shots.py --drift 0.5 "$W/results/ad-true"
echo "records under $W: step-7500/, validation/, results/, report*/, first-run/"
