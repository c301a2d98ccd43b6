"""HalfCheetah-Vel: a model's mean x-velocity per half-episode against the target (the README's tables).

    python docs/results/meta-rl/vel_speeds.py CHECKPOINT    # cold: env seeds 113, 102, 105, 100, 4 episodes each
    python docs/results/meta-rl/vel_speeds.py CHECKPOINT --prompt-from DATA

With --prompt-from, each of the first 6 HalfCheetah-Vel histories of dataset DATA prompts a run: its first 200 rows
(the demonstrator's probe), on its own env seed; then the model plays 3 episodes.
"""

import argparse
from pathlib import Path

import numpy as np

from vintix.agent import Agent
from vintix.data.hdf5 import LearningHistory
from vintix.tasks import make_env

TASK = "HalfCheetah-Vel-v5"


def half_episode_speeds(agent: Agent, seed: int, episodes: int, prompt: dict[str, np.ndarray] | None) -> str:
    """Mean x-velocity of each half of `episodes` episodes the agent plays on env `seed` (after `prompt`, if any)."""
    env = make_env(TASK, seed=seed)
    agent.reset([TASK], [env.action_space], discard_context=True)
    reward = 0.0
    if prompt is not None:
        agent.prompt(*([prompt[key]] for key in ("observation", "action", "reward", "step_num")))
        reward = float(prompt["reward"][-1])
    halves = []
    for _ in range(episodes):
        obs, _ = env.reset()
        start, speeds = True, []
        for _ in range(200):
            action, _ = agent.predict(obs, reward, start)
            obs, reward, _, _, info = env.step(action)
            start = False
            speeds.append(info["x_velocity"])
        halves.append(f"{np.mean(speeds[:100]):.2f}, {np.mean(speeds[100:]):.2f}")
    return f"target {env.unwrapped.true_goal[0]:.2f}: " + " | ".join(halves)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("checkpoint")
    parser.add_argument("--prompt-from", type=Path, help="a dataset root with HalfCheetah-Vel histories")
    args = parser.parse_args()
    agent = Agent.from_pretrained(args.checkpoint, threads=1)
    if args.prompt_from is None:
        for seed in (113, 102, 105, 100):
            print(half_episode_speeds(agent, seed, 4, None), flush=True)
        return
    for path in sorted((args.prompt_from / "mujoco" / TASK).glob("*.h5"))[:6]:
        with LearningHistory(path) as history:
            rows, seed = history.read(0, 200), history.env_seed
        print(half_episode_speeds(agent, int(seed), 3, rows), flush=True)


if __name__ == "__main__":
    main()
