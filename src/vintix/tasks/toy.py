"""A toy hidden-goal task: the smallest problem where only rewards can reveal what to do.

`point-goal-v1` is a point on a line that must end its episodes at a hidden goal, a miniature of
Meta-World's reach-v3 (one dimension instead of three): the point starts at the same place every
episode, the goal is drawn once per env from its seed and never observed, and the dense reward says
how far the point is from it. The goal is as likely left as right of the start, so an agent that
ignores rewards can only stay near the middle (success on about 10 % of goals), and so does a model
that predicts the mean action of a demonstrator who guesses: where left and right are equally likely
the mean is to stand still, which teaches nothing. A demonstrator that probes both ends in its first
episode and then goes to the most likely goal (`PosteriorSettings.probe_steps`) can be imitated, and
a small model trained on its histories learns, in CPU minutes, to find the goal from the rewards of
its first episode. The test suite uses it to check that the whole chain (collection, training, the
agent) keeps the model's use of rewards alive.

It is not a task of the paper: no published scores, domain ``toy``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

EPISODE_LENGTH = 10
START = np.array([0.0])
GOAL_LOW, GOAL_HIGH = np.array([-1.0]), np.array([1.0])
SPEED = 0.25
"""How far one step at full action moves the point: 4 of the 10 steps reach any goal."""
SUCCESS_RADIUS = 0.1
REWARD_DISTANCE_SCALE = 2.0
"""Rewards fall linearly with distance, reaching 0 at the farthest a point can be from a goal."""


class PointGoalEnv(gym.Env):
    """A point on a line with a hidden goal; obs is the point's position, action its velocity."""

    metadata = {"render_modes": []}

    def __init__(self, seed: int | None = None) -> None:
        self.observation_space = gym.spaces.Box(-2.0, 2.0, shape=START.shape, dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=START.shape, dtype=np.float32)
        self._position = START.copy()
        self._steps = 0
        self._draw_goal(seed)

    def _draw_goal(self, seed: int | None) -> None:
        self._goal = np.random.default_rng(seed).uniform(GOAL_LOW, GOAL_HIGH)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """`seed` draws the goal anew, exactly as a new env with that seed would; otherwise the goal stays."""
        super().reset(seed=seed)
        if seed is not None:
            self._draw_goal(seed)
        self._position, self._steps = START.copy(), 0
        return self._position.astype(np.float32), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        action = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        self._position = np.clip(self._position + SPEED * action, -2.0, 2.0)
        self._steps += 1
        reward = float(self.rewards_under_goals(self._goal[None])[0])
        truncated = self._steps >= EPISODE_LENGTH
        # Success is ending the episode at the goal: sweeping past it on the way does not count.
        success = float(truncated and np.linalg.norm(self._position - self._goal) < SUCCESS_RADIUS)
        return self._position.astype(np.float32), reward, False, truncated, {"success": success}

    # What a goal-inferring demonstrator may use (never a model): the prior over goals, the reward the
    # current state would earn under other goals, and the true goal.

    def goal_box(self) -> tuple[np.ndarray, np.ndarray]:
        """The bounds of the hidden goal."""
        return GOAL_LOW.copy(), GOAL_HIGH.copy()

    def goal_prior(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """`count` goals drawn from the distribution the env draws its hidden goal from."""
        return rng.uniform(GOAL_LOW, GOAL_HIGH, size=(count, len(START)))

    def rewards_under_goals(self, goals: np.ndarray, action: np.ndarray | None = None) -> np.ndarray:
        """The reward of the current state had the goal been each of `goals` ``[n, 1]``."""
        return 1.0 - np.linalg.norm(self._position - goals, axis=-1) / REWARD_DISTANCE_SCALE

    @property
    def true_goal(self) -> np.ndarray:
        """The hidden goal. For demonstrators only."""
        return self._goal.copy()


def action_toward(observations: np.ndarray, goals: np.ndarray) -> np.ndarray:
    """The expert's action: straight at the goal, as fast as the action bounds allow."""
    return np.clip((goals - observations) / SPEED, -1.0, 1.0)
