#!/usr/bin/env bash
# The discrete benchmarks' comparison (README.md here): each history source on each task, from nothing, with the
# reward ablation. WORK default: icrl-benchmarks/. Each cell: scripts/icrl_benchmark.sh (collect, train, evaluate on
# held-out goals with true / zero / shuffled rewards, report, times.txt).
set -euo pipefail
cd "$(dirname "$0")/../../.."
W=${1:-icrl-benchmarks}
cell() { scripts/icrl_benchmark.sh "$1" "$2" "$3" "$W/$1"; }
cell darkroom-ad darkroom-ad DarkRoom-heldout-v0
cell darkroom-adeps darkroom DarkRoom-heldout-v0
cell darkroom-search darkroom-search DarkRoom-heldout-v0      # DART (the shipped darkroom); the 15- and 40-episode
                                                              # variants: the recipe's earlier versions (README)
cell keytodoor-search keytodoor-search KeyToDoor-heldout-v0  # DART; keytodoor-search-first/: the recipe's first version
cell keytodoor-ad keytodoor-ad KeyToDoor-heldout-v0
# a clean search for 20 %, then DART (the recipe beside its records), and the same data with Fourier position codes
R=docs/results/icrl-benchmarks
scripts/icrl_benchmark.sh $R/keytodoor-cleansearch/recipe.yaml keytodoor-search KeyToDoor-heldout-v0 "$W/keytodoor-cleansearch"
scripts/icrl_benchmark.sh $R/keytodoor-cleansearch/recipe.yaml $R/keytodoor-fourier/config.yaml KeyToDoor-heldout-v0 \
  "$W/keytodoor-fourier"
scripts/icrl_benchmark.sh $R/keytodoor-cleansearch/recipe.yaml $R/keytodoor-lastaction/config.yaml KeyToDoor-heldout-v0 \
  "$W/keytodoor-lastaction"
# the same run resumed to 3,000 steps, twice its budget (the cosine restarts from step 1,500)
mkdir -p "$W/keytodoor-lastaction-3000" && cp -rn "$W/keytodoor-lastaction/data" "$W/keytodoor-lastaction/run" \
  "$W/keytodoor-lastaction-3000/"
TRAIN_ARGS="--set max_steps=3000" scripts/icrl_benchmark.sh $R/keytodoor-cleansearch/recipe.yaml \
  $R/keytodoor-lastaction/config.yaml KeyToDoor-heldout-v0 "$W/keytodoor-lastaction-3000"
# AD^ε's random start each episode, the same clean search and model
scripts/icrl_benchmark.sh $R/keytodoor-randomstart/recipe.yaml $R/keytodoor-lastaction/config.yaml \
  KeyToDoorRandomStart-heldout-v0 "$W/keytodoor-randomstart"
mkdir -p "$W/keytodoor-randomstart-3000" && cp -rn "$W/keytodoor-randomstart/data" "$W/keytodoor-randomstart/run" \
  "$W/keytodoor-randomstart-3000/"
TRAIN_ARGS="--set max_steps=3000" scripts/icrl_benchmark.sh $R/keytodoor-randomstart/recipe.yaml \
  $R/keytodoor-lastaction/config.yaml KeyToDoorRandomStart-heldout-v0 "$W/keytodoor-randomstart-3000"
# the same data, each token also carrying what its episode earned before it (episode_return: whether the key is held)
mkdir -p "$W/keytodoor-episodereturn" && cp -rn "$W/keytodoor-randomstart/data" "$W/keytodoor-episodereturn/"
scripts/icrl_benchmark.sh $R/keytodoor-randomstart/recipe.yaml $R/keytodoor-episodereturn/config.yaml \
  KeyToDoorRandomStart-heldout-v0 "$W/keytodoor-episodereturn"
cell keytodoor-adeps keytodoor KeyToDoor-heldout-v0
# a search the model can copy (the shipped keytodoor), on 64 more pairs too, greedy, and its sampled trace on seed 100
cell keytodoor-walk keytodoor-walk KeyToDoor-heldout-v0
for rewards in true zero shuffled; do
  vintix eval --checkpoint "$W/keytodoor-walk/run" --tasks KeyToDoor-heldout-v0 --shots 40 --seeds 64 --first-seed 200 \
    --reward-input "$rewards" --label "keytodoor-walk, 64 more pairs" --out "$W/keytodoor-walk/results-64/$rewards"
done
vintix report "$W"/keytodoor-walk/results-64/{true,zero,shuffled} --out "$W/keytodoor-walk/report-64"
vintix eval --checkpoint "$W/keytodoor-walk/run" --tasks KeyToDoor-heldout-v0 --shots 40 --seeds 16 --first-seed 100 \
  --greedy --out "$W/keytodoor-walk/results/true-greedy"
python scripts/grid_trace.py "$W/keytodoor-walk/run" --seed 100 --sample --episodes 40 \
  > "$W/keytodoor-walk/trace-seed100-sampled.txt"
# Key-to-Door prompted with its search demonstrator's first 150 steps (its rewards kept, then zeroed), 20 held-out pairs
vintix collect --recipe $R/keytodoor-prompted/recipe.yaml --out "$W/keytodoor-prompted/data" --workers 1
cp -r "$W/keytodoor-prompted/data" "$W/keytodoor-prompted/data-zeroed"
python - "$W/keytodoor-prompted/data-zeroed" <<'PY'
import sys
from pathlib import Path
import h5py
def zero_rewards(name, dataset):
    if name.endswith("/reward"):
        dataset[...] = 0
for path in Path(sys.argv[1]).glob("icrl/*/*.h5"):
    with h5py.File(path, "r+") as f:
        f.visititems(zero_rewards)
PY
for model in keytodoor-lastaction keytodoor-search; do
  for prompt in data data-zeroed; do
    vintix eval --checkpoint "$W/$model/run" --tasks KeyToDoor-heldout-v0 --shots 10 --seeds 20 --first-seed 100 \
      --prompt-from "$W/keytodoor-prompted/$prompt" --prompt-steps 150 --out "$W/keytodoor-prompted/$model-${prompt/data/prompt}"
  done
done
cell bandit-ad bandit BernoulliBandit-v0                      # the shipped bandit
cell bandit-adeps bandit BernoulliBandit-v0
cell bandit-posterior bandit BernoulliBandit-v0
# Dark Room Hard: the Dark Room configs, selecting their checkpoints on the hard room
cell darkroomhard-search darkroom-search DarkRoomHard-heldout-v0
TRAIN_ARGS="--set select_tasks=[DarkRoomHard-v0]" cell darkroomhard-ad darkroom-ad DarkRoomHard-heldout-v0
TRAIN_ARGS="--set select_tasks=[DarkRoomHard-v0]" cell darkroomhard-adeps darkroom DarkRoomHard-heldout-v0
# Greedy actions (greedy/ here): the same checkpoints, argmax instead of a draw.
for source in darkroom-ad darkroom-adeps darkroom-search; do
  vintix eval --checkpoint "$W/$source/run" --tasks DarkRoom-heldout-v0 --shots 40 --seeds 16 --first-seed 100 --greedy \
    --out "$W/greedy/$source"
done
vintix eval --checkpoint "$W/darkroom-search/run" --tasks DarkRoom-heldout-v0 --shots 40 --seeds 16 --first-seed 100 \
  --greedy --reward-input zero --out "$W/greedy/darkroom-search-zero"
python scripts/bandit_baselines.py "$W"/bandit-{ad,adeps,posterior}/results/{true,zero,shuffled}
