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
python - "$W/runs/ad/checkpoints/best" <<'PY'
import sys
import numpy as np
from vintix.agent import Agent
from vintix.tasks import make_env
agent = Agent.from_pretrained(sys.argv[1], threads=1)
for seed in (113, 102, 105, 100):
    env = make_env("HalfCheetah-Vel-v5", seed=seed)
    agent.reset(["HalfCheetah-Vel-v5"], [env.action_space], discard_context=True)
    halves = []
    for _ in range(4):
        obs, _ = env.reset()
        reward, start, speeds = 0.0, True, []
        for _ in range(200):
            action, _ = agent.predict(obs, reward, start)
            obs, reward, terminated, truncated, info = env.step(action)
            start = False
            speeds.append(info["x_velocity"])
        halves.append(f"{np.mean(speeds[:100]):.2f}, {np.mean(speeds[100:]):.2f}")
    print(f"target {env.unwrapped.true_goal[0]:.2f}:", " | ".join(halves))
PY
