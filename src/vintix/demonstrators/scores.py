"""Measuring our own reference scores: each demonstrator's and a uniform-random policy's return, played here.

`vintix demonstrator eval` measures them (`measure`) into a score table; reading that table and
normalizing by it is the task registry's business (`vintix.tasks.scores`), as the paper's published
scores are.
"""

from __future__ import annotations

import datetime
from collections.abc import Sequence
from importlib import metadata

import gymnasium as gym
import numpy as np

from vintix.demonstrators.base import Demonstrator
from vintix.tasks import TaskSpec, get_task, make_env
from vintix.tasks.scores import MeasuredScore

_DOMAIN_PACKAGES = {"mujoco": "mujoco", "metaworld": "metaworld", "industrial_benchmark": "industrial-benchmark-python"}


class UniformRandomPolicy:
    """Uniform-random actions from each env's own (seeded) action space."""

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        return np.stack([env.action_space.sample() for env in envs])


def env_version(spec: TaskSpec) -> str:
    package = _DOMAIN_PACKAGES.get(spec.domain)
    return f"{spec.name}, {package} {metadata.version(package)}" if package else spec.name


def episode_returns(task: str, policy: Demonstrator, episodes: int, seed: int = 0) -> np.ndarray:
    """One episode in each of `episodes` envs (env i seeded `seed + i`: for Meta-World, its own hidden
    goal), stepped in lockstep so the policy acts on a batch; returns their undiscounted returns."""
    return episode_outcomes(task, policy, episodes, seed)[0]


def episode_outcomes(task: str, policy: Demonstrator, episodes: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """`episode_returns`, and each episode's success (1 if the env flagged success at any step, else 0)."""
    envs = [make_env(task, seed=seed + i) for i in range(episodes)]
    observations = np.stack([env.reset()[0] for env in envs])
    returns, success = np.zeros(episodes), np.zeros(episodes)
    running = np.ones(episodes, dtype=bool)
    while running.any():
        active = np.flatnonzero(running)
        actions = policy.act(observations[active], [envs[i] for i in active])
        for i, action in zip(active, actions, strict=True):
            observations[i], reward, terminated, truncated, info = envs[i].step(action)
            returns[i] += float(reward)
            success[i] = max(success[i], float(info.get("success", 0.0)))
            running[i] = not (terminated or truncated)
    for env in envs:
        env.close()
    return returns, success


def measure(task: str, policy_name: str, policy: Demonstrator, episodes: int, seed: int, command: str) -> MeasuredScore:
    """Run `policy` and describe its returns as a score-table row."""
    spec = get_task(task)
    returns = episode_returns(spec.name, policy, episodes, seed)
    return MeasuredScore(spec.name, policy_name, round(float(returns.mean()), 3), round(float(returns.std()), 3),
                         episodes, seed, env_version(spec), datetime.date.today().isoformat(), command)
