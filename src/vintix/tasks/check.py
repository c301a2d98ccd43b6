"""Check environments against the paper: a uniform-random policy's return, and raw env speed.

The paper publishes each task's random-policy score; ours should fall inside it up to env-version
drift (MuJoCo v4→v5, Meta-World v2→v3). This also measures env steps/s, the budget everything
downstream (collection, evaluation) is planned from.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from vintix.tasks.make import make_env
from vintix.tasks.registry import get_task


@dataclass(frozen=True)
class RandomPolicyResult:
    """Episode returns of a uniform-random policy on one task."""

    task: str
    returns: tuple[float, ...]
    steps: int
    seconds: float
    seed: int

    @property
    def mean(self) -> float:
        return float(np.mean(self.returns))

    @property
    def std(self) -> float:
        return float(np.std(self.returns))

    @property
    def steps_per_second(self) -> float:
        return self.steps / self.seconds

    @property
    def paper_z(self) -> float | None:
        """How many of the paper's random-score standard deviations our mean lies from the paper's."""
        paper = get_task(self.task).paper_random
        if paper is None or not paper.std:
            return None
        return (self.mean - paper.mean) / paper.std


def random_policy_returns(task: str, episodes: int, seed: int = 0) -> RandomPolicyResult:
    """Run `episodes` episodes of uniform-random actions (the action space seeded with `seed`)."""
    env = make_env(task, seed=seed)
    returns, steps = [], 0
    start = time.perf_counter()
    for _ in range(episodes):
        env.reset()
        episode_return, done = 0.0, False
        while not done:
            _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            episode_return += float(reward)
            steps += 1
            done = terminated or truncated
        returns.append(episode_return)
    seconds = time.perf_counter() - start
    env.close()
    return RandomPolicyResult(get_task(task).name, tuple(returns), steps, seconds, seed)
