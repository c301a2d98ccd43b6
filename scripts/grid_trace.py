"""Episode-by-episode trace of a model on a room task (Dark Room, Key-to-Door): where it was paid and where it went.

    python scripts/grid_trace.py CHECKPOINT [--task KeyToDoor-heldout-v0] [--seed 100] [--episodes 6] [--sample]

Plays one env of the task (its hidden goal drawn from --seed) from an empty context, greedy unless --sample, and
prints each episode's return, the cells it was paid at, and its path (the first 60 cells).
"""

from __future__ import annotations

import argparse

from vintix.agent import Agent
from vintix.tasks import make_env


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkpoint")
    parser.add_argument("--task", default="KeyToDoor-heldout-v0")
    parser.add_argument("--seed", type=int, default=100)
    parser.add_argument("--episodes", type=int, default=6)
    parser.add_argument("--sample", action="store_true", help="draw actions from the logits instead of the argmax")
    args = parser.parse_args()
    env = make_env(args.task, seed=args.seed)
    agent = Agent.from_pretrained(args.checkpoint, threads=1)
    agent.reset([args.task])
    obs, _ = env.reset()
    print(f"{args.task}, seed {args.seed}: hidden {env.unwrapped.true_goal.tolist()}")  # type: ignore[attr-defined]
    reward, start = 0.0, True
    for episode in range(1, args.episodes + 1):
        path, paid, episode_return, done = [tuple(int(v) for v in obs)], [], 0.0, False
        while not done:
            action = agent.act([obs], [reward], [start], deterministic=not args.sample)[0]
            obs, reward, terminated, truncated, _ = env.step(int(action))
            path.append(tuple(int(v) for v in obs))
            episode_return += float(reward)
            if reward:
                paid.append(path[-1])
            start, done = False, terminated or truncated
        print(f"episode {episode}: return {episode_return:g}, {len(path) - 1} steps, paid at {paid}, path {path[:60]}")
        obs, _ = env.reset()
        start = True


if __name__ == "__main__":
    main()
