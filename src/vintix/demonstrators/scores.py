"""Measuring our own reference scores: each demonstrator's and a uniform-random policy's return, played here.

`vintix demonstrator eval` measures them (`measure`) into a score table; reading that table and
normalizing by it is the task registry's business (`vintix.tasks.scores`), as the paper's published
scores are.
"""

from __future__ import annotations

import datetime
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import metadata

import gymnasium as gym
import numpy as np

from vintix.demonstrators.base import Demonstrator
from vintix.demonstrators.posterior import GoalInferringDemonstrator
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


@dataclass(frozen=True)
class HistoryOutcomes:
    """What a demonstrator that learns within a history did in each of its episodes, per env
    (arrays [n_envs, episodes])."""

    returns: np.ndarray
    """undiscounted return of each episode"""
    success: np.ndarray
    """1 if the env flagged success at any step of the episode, else 0"""
    end_distance: np.ndarray
    """the env's distance from object to goal at the episode's last step (``info['obj_to_target']``; on
    Meta-World reach the gripper centre's, whose distance success measures); NaN where the env has none"""


def history_outcomes(task: str, demonstrator: GoalInferringDemonstrator, seeds: Sequence[int],
                     episodes: int) -> HistoryOutcomes:
    """Play one history of `episodes` episodes per env seed (each its own hidden goal, its demonstrator
    random stream seeded alike), told every step's reward as the collector tells it, with no noise:
    how the demonstrator alone does, episode after episode."""
    envs = [make_env(task, seed=seed) for seed in seeds]
    demonstrator.begin(envs, [np.random.default_rng(seed) for seed in seeds])
    shape = (len(envs), episodes)
    returns, success, end_distance = np.zeros(shape), np.zeros(shape), np.full(shape, np.nan)
    for episode in range(episodes):
        observations = np.stack([env.reset()[0] for env in envs])
        running = np.ones(len(envs), dtype=bool)
        while running.any():
            actions = demonstrator.act(observations, envs)  # every env's episode has the same length
            for i in np.flatnonzero(running):
                observations[i], reward, terminated, truncated, info = envs[i].step(actions[i])
                returns[i, episode] += float(reward)
                success[i, episode] = max(success[i, episode], float(info.get("success", 0.0)))
                running[i] = not (terminated or truncated)
                if not running[i]:
                    end_distance[i, episode] = float(info.get("obj_to_target", np.nan))
                demonstrator.observe(int(i), envs[i], actions[i], float(reward), not running[i])
    for env in envs:
        env.close()
    return HistoryOutcomes(returns, success, end_distance)


def measure(task: str, policy_name: str, policy: Demonstrator, episodes: int, seed: int, command: str) -> MeasuredScore:
    """Run `policy` and describe its returns as a score-table row."""
    spec = get_task(task)
    returns = episode_returns(spec.name, policy, episodes, seed)
    return MeasuredScore(spec.name, policy_name, round(float(returns.mean()), 3), round(float(returns.std()), 3),
                         episodes, seed, env_version(spec), datetime.date.today().isoformat(), command)
