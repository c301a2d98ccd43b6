#!/usr/bin/env bash
# The discrete benchmarks' comparison (README.md here): each history source on each task, from nothing, with the
# reward ablation. WORK default: icrl-benchmarks/. Each cell: scripts/icrl_benchmark.sh (collect, train, evaluate on
# held-out goals with true / zero / shuffled rewards, report, times.txt).
set -euo pipefail
cd "$(dirname "$0")/../../.."
W=${1:-icrl-benchmarks}
cell() { scripts/icrl_benchmark.sh "$1" "$2" "$3" "$W/$1"; }
cell darkroom-search darkroom DarkRoom-heldout-v0
cell darkroom-posterior darkroom DarkRoom-heldout-v0
cell darkroom-adeps darkroom DarkRoom-heldout-v0
cell darkroom-ad darkroom-ad DarkRoom-heldout-v0
cell bandit-posterior bandit BernoulliBandit-v0
cell keytodoor-search keytodoor KeyToDoor-heldout-v0
python scripts/bandit_baselines.py "$W/bandit-posterior/results/true"
