#!/usr/bin/env bash
# The flagship retrained with the meta-RL tasks (README.md here), on a CPU; collection and training resume where
# they stopped, so the run may span sessions:
#   docs/results/vintix-cpu-meta/run.sh [WORK_DIR]      (default work/vintix-cpu-meta)
set -euo pipefail
cd "$(dirname "$0")/../../.."
D=docs/results/vintix-cpu-meta
W=${1:-work/vintix-cpu-meta}
vintix collect --recipe $D/recipe.yaml --out "$W/data" --workers 2
vintix train --config $D/config.yaml --data "$W/data" --out "$W/runs/ad"
