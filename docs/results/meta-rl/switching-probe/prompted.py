"""HalfCheetah-Vel with the switching probe (commit ad013f6, before recipe meta-mujoco's probe stood still): the
model prompted with its demonstrator's probe (a training history's first 200 rows, on that history's env seed),
then 3 episodes of its own; prints the mean x-velocity per half-episode against the target.

    python switching-probe/prompted.py WORK/runs/ad/checkpoints/best WORK/data
"""

import sys
from pathlib import Path

import numpy as np

from vintix.agent import Agent
from vintix.data.hdf5 import LearningHistory
from vintix.tasks import make_env

agent = Agent.from_pretrained(sys.argv[1], threads=1)
for path in sorted(Path(sys.argv[2]).glob("mujoco/HalfCheetah-Vel-v5/*.h5"))[:6]:
    with LearningHistory(path) as history:
        rows, seed = history.read(0, 200), history.env_seed
    env = make_env("HalfCheetah-Vel-v5", seed=seed)
    agent.reset(["HalfCheetah-Vel-v5"], [env.action_space], discard_context=True)
    agent.prompt([rows["observation"]], [rows["action"]], [rows["reward"]], [rows["step_num"]])
    reward, halves = float(rows["reward"][-1]), []
    for _ in range(3):
        obs, _ = env.reset()
        start, speeds = True, []
        for _ in range(200):
            action, _ = agent.predict(obs, reward, start)
            obs, reward, _, _, info = env.step(action)
            start = False
            speeds.append(info["x_velocity"])
        halves.append(f"{np.mean(speeds[:100]):.2f}, {np.mean(speeds[100:]):.2f}")
    probe = f"{rows['reward'][:100].mean():.2f}, {rows['reward'][100:].mean():.2f}"
    print(f"target {env.unwrapped.true_goal[0]:.2f}: probe rewards {probe} |", " | ".join(halves), flush=True)
