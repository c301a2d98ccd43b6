"""Scripted experts: Meta-World's (`metaworld.policies`, one per task), the toy task's and the hidden Reacher's.

Meta-World's read the goal from the last 3 observation entries, which the ML45 setting hides; the env
gives the true goal to demonstrators through `expert_observation`. The model never sees it. Both can
also aim at a goal they are given (`act_toward`), which is how a demonstrator that does not know the
goal plays its current guess (`vintix.demonstrators.posterior`). On reach tasks Meta-World's policy can
aim the gripper centre at the goal instead of the hand (`vintix.demonstrators.base.AIMS`).
"""

from __future__ import annotations

from collections.abc import Sequence

import gymnasium as gym
import numpy as np
from metaworld.policies import ENV_POLICY_MAP

from vintix.demonstrators.base import check_aim
from vintix.tasks import reacher_hidden, toy
from vintix.tasks.metaworld import hand_to_gripper_centre


class ScriptedMetaWorldDemonstrator:
    """The scripted policy of one Meta-World task, aiming its hand or its gripper centre at the goal
    (`vintix.demonstrators.base.AIMS`)."""

    def __init__(self, task: str, aim: str = "hand") -> None:
        # The map holds each task's concrete policy class; metaworld types its values as the abstract base.
        self.policy = ENV_POLICY_MAP[task]()  # type: ignore[abstract]
        check_aim(task, aim)
        self.aim_offset = hand_to_gripper_centre(task) if aim == "gripper-centre" else np.zeros(3)

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        return self.act_toward(observations, np.stack([env.unwrapped.true_goal for env in envs]))  # type: ignore[attr-defined]

    def act_toward(self, observations: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """What the policy does if the hidden goal is `goals` ``[n_envs, 3]`` (one guess per env)."""
        full = np.array(observations, dtype=np.float64, copy=True)
        full[:, -3:] = goals + self.aim_offset
        return np.stack([self.policy.get_action(o) for o in full])

    @staticmethod
    def fumble(actions: np.ndarray) -> np.ndarray:
        """`actions` with the gripper held open (its effort, the 4th entry, at -1): the object is never held."""
        fumbled = np.array(actions, copy=True)
        fumbled[:, 3] = -1.0
        return fumbled


class ScriptedPointGoalDemonstrator:
    """The toy task's expert (`vintix.tasks.toy`): straight at the goal."""

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        return self.act_toward(observations, np.stack([env.unwrapped.true_goal for env in envs]))  # type: ignore[attr-defined]

    def act_toward(self, observations: np.ndarray, goals: np.ndarray) -> np.ndarray:
        return toy.action_toward(np.asarray(observations, dtype=np.float64), goals)


class ScriptedReacherDemonstrator:
    """`Reacher-hidden-v5`'s expert (`vintix.tasks.reacher_hidden.action_toward`): inverse kinematics and a
    PD controller, aimed at the true target."""

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        return self.act_toward(observations, np.stack([env.unwrapped.true_goal for env in envs]))  # type: ignore[attr-defined]

    def act_toward(self, observations: np.ndarray, goals: np.ndarray) -> np.ndarray:
        return reacher_hidden.action_toward(np.asarray(observations, dtype=np.float64), goals)
