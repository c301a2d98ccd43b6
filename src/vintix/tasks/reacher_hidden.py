"""`Reacher-hidden-v5`: gymnasium's Reacher-v5 with its target hidden, so only the rewards reveal it.

Reacher-v5 shows the target twice (its coordinates and the fingertip-to-target vector), so a model can
reach it by imitation alone. Here the model sees the arm only: the cosines and sines of both joint
angles and their velocities (6 entries). The reward is Reacher's own, minus the fingertip's distance
to the target minus the squared action, so the rewards give the distance exactly and a short probe of
the arm's workspace locates the target.

Protocol, as Meta-World's hidden-goal tasks (`vintix.tasks.metaworld`): an env keeps one target for its
whole life, drawn from its seed the way Reacher draws its own (uniform in the disc of radius 0.2 m), so
an agent can infer it across episodes. The arm's start is Reacher's (joint angles within 0.1 rad of
straight, fresh every episode).

Success (`info["success"]`): the fingertip within `SUCCESS_RADIUS` of the target at the episode's last
step, as Meta-World's reach measures 5 cm. A dense return hides what the target decides: measured on
Reacher-v5 (40 seeds), the shipped trained expert returns -4.8 and a copy of it aimed at the middle of
the target disc -8.6, yet the first ends within 5 cm in 68 % of its episodes and the second in none.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.mujoco.reacher_v5 import ReacherEnv

TARGET_RADIUS = 0.2
"""Reacher draws its target uniformly in the disc of this radius (m) around the arm's base."""
SUCCESS_RADIUS = 0.05
"""Success is the fingertip this near the target (m) when the episode ends."""
LINK_LENGTHS = (0.1, 0.11)
"""Base to elbow, elbow to fingertip (m), from Reacher's MJCF."""
HIDDEN_OBSERVATION_NAMES = ("cos_q1", "cos_q2", "sin_q1", "sin_q2", "qvel_1", "qvel_2")
_VISIBLE = [0, 1, 2, 3, 6, 7]
"""Which of Reacher-v5's 10 observation entries the hidden task keeps: its target coordinates (4, 5) and
fingertip-to-target vector (8, 9) go."""


def joint_angles(observations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both joint angles from hidden observations ``[..., 6]`` (cosines, then sines)."""
    cosines, sines = observations[..., 0:2], observations[..., 2:4]
    return np.arctan2(sines[..., 0], cosines[..., 0]), np.arctan2(sines[..., 1], cosines[..., 1])


def fingertip_position(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Where the fingertip is ``[..., 2]`` with the joints at `q1`, `q2` (forward kinematics)."""
    l1, l2 = LINK_LENGTHS
    return np.stack([l1 * np.cos(q1) + l2 * np.cos(q1 + q2), l1 * np.sin(q1) + l2 * np.sin(q1 + q2)], axis=-1)


def sample_targets(rng: np.random.Generator, count: int) -> np.ndarray:
    """`count` targets ``[count, 2]`` drawn as Reacher draws its own: uniform in the disc, by rejection."""
    targets = np.empty((0, 2))
    while len(targets) < count:
        draws = rng.uniform(-TARGET_RADIUS, TARGET_RADIUS, size=(2 * count, 2))
        targets = np.concatenate([targets, draws[np.linalg.norm(draws, axis=1) < TARGET_RADIUS]])
    return targets[:count]


class ReacherHiddenEnv(gym.Env):
    """Reacher-v5 with a hidden target kept for the env's life; obs: joint cosines, sines, velocities."""

    metadata = {"render_modes": ["human", "rgb_array", "depth_array"]}

    def __init__(self, seed: int | None = None, episode_length: int = 50, render_mode: str | None = None) -> None:
        self._reacher = ReacherEnv(render_mode=render_mode)
        self.episode_length = episode_length
        self.render_mode = render_mode
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(len(_VISIBLE),), dtype=np.float64)
        self.action_space = self._reacher.action_space
        self._steps = 0
        self._draw_target(seed)

    def _draw_target(self, seed: int | None) -> None:
        self._target = sample_targets(np.random.default_rng(seed), 1)[0]

    @property
    def model(self) -> Any:
        """The MuJoCo model, so physics variations (`vintix.tasks.mujoco`) apply as to any MuJoCo task."""
        return self._reacher.model

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """`seed` draws the target anew, exactly as a new env with that seed would; otherwise it stays."""
        super().reset(seed=seed)
        if seed is not None:
            self._draw_target(seed)
        self._reacher.reset(seed=int(self.np_random.integers(2**31 - 1)))
        # Reacher drew a target of its own: put ours in its place (the target's slide joints are its position).
        data = self._reacher.data
        qpos, qvel = data.qpos.copy(), data.qvel.copy()
        qpos[-2:] = self._target
        self._reacher.set_state(qpos, qvel)
        self._steps = 0
        return self._hide(self._reacher._get_obs()), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        obs, reward, _, _, info = self._reacher.step(action)
        self._steps += 1
        truncated = self._steps >= self.episode_length
        distance = float(np.linalg.norm(self._fingertip() - self._target))
        # Success is ending the episode at the target: sweeping past it on the way does not count.
        # The distance under Meta-World's name for it, which `vintix demonstrator histories` reports.
        info |= {"success": float(truncated and distance < SUCCESS_RADIUS), "obj_to_target": distance}
        return self._hide(obs), float(reward), False, truncated, info

    @staticmethod
    def _hide(obs: np.ndarray) -> np.ndarray:
        return np.asarray(obs, dtype=np.float64)[_VISIBLE]

    def _fingertip(self) -> np.ndarray:
        return np.asarray(self._reacher.get_body_com("fingertip")[:2], dtype=np.float64)

    # What a goal-inferring demonstrator may use (never a model): the prior over targets, the reward the
    # last step would have earned under other targets, and the true target.

    def goal_box(self) -> tuple[np.ndarray, np.ndarray]:
        """The bounds of the hidden target (the square around the disc it is drawn in)."""
        return np.full(2, -TARGET_RADIUS), np.full(2, TARGET_RADIUS)

    def goal_prior(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """`count` targets drawn from the distribution the env draws its own from."""
        return sample_targets(rng, count)

    def rewards_under_goals(self, goals: np.ndarray, action: np.ndarray) -> np.ndarray:
        """The reward of the last step (`action`) had the target been each of `goals` ``[n, 2]``: Reacher-v5's
        reward, minus the distance minus the squared action."""
        control = float(np.square(action).sum())
        return -np.linalg.norm(self._fingertip() - goals, axis=-1) - control

    @property
    def true_goal(self) -> np.ndarray:
        """The hidden target. For demonstrators only."""
        return self._target.copy()

    def render(self) -> Any:
        return self._reacher.render()

    def close(self) -> None:
        self._reacher.close()


def action_toward(observations: np.ndarray, goals: np.ndarray, gain: float = 0.5, damping: float = 0.1) -> np.ndarray:
    """The scripted expert: inverse kinematics for the two-link arm, then a PD controller on the joint angles.

    Of the two elbow solutions it takes the one nearer the arm's current angles; a target the arm cannot
    reach (nearer the base than the links' difference, or beyond their sum) is replaced by the nearest point
    it can. Gains measured on Reacher-v5 (100 seeds, the true target): every episode ends within 1 mm of the
    target, mean return -4.19 (the shipped trained expert: -4.5)."""
    q1, q2 = joint_angles(observations)
    l1, l2 = LINK_LENGTHS
    distance = np.clip(np.linalg.norm(goals, axis=-1), abs(l1 - l2) + 1e-6, l1 + l2 - 1e-6)
    elbow = np.arccos(np.clip((distance**2 - l1**2 - l2**2) / (2 * l1 * l2), -1.0, 1.0))
    bearing = np.arctan2(goals[..., 1], goals[..., 0])
    solutions = [(bearing - np.arctan2(l2 * np.sin(e), l1 + l2 * np.cos(e)), e) for e in (elbow, -elbow)]
    errors = [np.stack([_wrap(t1 - q1), t2 - q2], axis=-1) for t1, t2 in solutions]
    nearer = np.abs(errors[0]).sum(-1) <= np.abs(errors[1]).sum(-1)
    error = np.where(nearer[..., None], errors[0], errors[1])
    return np.clip(gain * error - damping * observations[..., 4:6], -1.0, 1.0)


def _wrap(angle: np.ndarray) -> np.ndarray:
    """`angle` into [-pi, pi): the base joint turns freely, so the short way round."""
    return (angle + np.pi) % (2 * np.pi) - np.pi
