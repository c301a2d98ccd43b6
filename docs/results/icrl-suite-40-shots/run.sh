#!/usr/bin/env bash
# icrl-suite over 40 shots, and the lapse fix tried on push alone (README.md here), from the shipped icrl-suite;
# writes into WORK the files this folder keeps, under the same names, and push-alone/episodes-{base,lapse}.csv,
# which it does not keep (regenerated here).
#   docs/results/icrl-suite-40-shots/run.sh WORK
# The 40-shot evaluations take about 30 min on one thread; push alone, two collections (7-11 min each) and two
# trainings of 1,500 steps (about 17 min each) and their evaluations.
set -euo pipefail
W=${1:?usage: docs/results/icrl-suite-40-shots/run.sh WORK}
HERE=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$W/push-alone"
W=$(cd "$W" && pwd)
cd "$HERE/../../.."
V=${VINTIX:-vintix}
PYTHON=${PYTHON:-python}

# 20 goals training never used, 40 shots, true rewards; each run's strip; where pick-place's object ends.
for t in push-v3 pick-place-v3; do
  $V eval --checkpoint icrl-suite --tasks $t --shots 40 --seeds 20 --first-seed 100 --reference ours \
    --threads 1 --out "$W/res40-$t"
  cp "$W/res40-$t/episodes.csv" "$W/episodes-$t.csv"
done
$PYTHON scripts/success_over_shots.py "$W/res40-push-v3" "$W/res40-pick-place-v3" --strips
$PYTHON scripts/goal_distance.py icrl-suite --task pick-place-v3 --point object --shots 40 --seeds 5 --first-seed 108 \
  --out "$W/end-distances-pick-place-v3-seeds-108-112.csv"

# The window check: the same weights with context_len 500 (as trained) and 1,000 at play time, seeds 100-105.
model=$($PYTHON -c "from vintix.agent.pretrained import resolve_checkpoint; print(resolve_checkpoint('icrl-suite'))")
for n in 500 1000; do
  mkdir -p "$W/window-$n" && cp "$model/model.safetensors" "$W/window-$n/"
  $PYTHON -c "import json, sys; c = json.load(open(sys.argv[1])); c['config']['context_len'] = int(sys.argv[2])
json.dump(c, open(sys.argv[3], 'w'), indent=1)" "$model/config.json" "$n" "$W/window-$n/config.json"
  $V eval --checkpoint "$W/window-$n" --tasks push-v3,pick-place-v3 --shots 40 --seeds 6 --first-seed 100 \
    --reference ours --threads 1 --out "$W/res-window-$n"
  cp "$W/res-window-$n/episodes.csv" "$W/episodes-push-pick-place-window-$n-seeds-100-105.csv"
done

# Push alone, without and with lapses (p = 0.3): icrl-reach's config on the suite's 400 push goals, then 40 shots on
# 60 unseen goals (env seeds 100-159: two evaluations of each model, joined into episodes-VARIANT.csv).
cd "$W/push-alone"
cp "$HERE"/push-alone/recipe-{base,lapse}.yaml .
for v in base lapse; do
  $V collect --recipe recipe-$v.yaml --out data-$v --workers 2
  $V train --config icrl-reach --data data-$v --out runs/$v --set 'tasks=[push-v3]' \
    --set 'select_tasks=[push-v3]' --set select_every=500 --set checkpoint_every=500 --set select_seeds=8
  $V eval --checkpoint runs/$v --tasks push-v3 --shots 40 --seeds 20 --first-seed 100 --reference ours --out res-$v
  $V eval --checkpoint runs/$v --tasks push-v3 --shots 40 --seeds 40 --first-seed 120 --reference ours \
    --out res-$v-more
  { cat res-$v/episodes.csv; tail -n +2 res-$v-more/episodes.csv; } > episodes-$v.csv
  cp runs/$v/log.csv training-log-$v.csv
done
echo "records under $W: episodes-*.csv, end-distances-*.csv, push-alone/episodes-{base,lapse}.csv"
