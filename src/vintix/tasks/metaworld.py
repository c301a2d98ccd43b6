"""Meta-World tasks in the ML45 setting: goal hidden, one goal per env, short episodes.

Protocol (ML45 meta-RL; docs/tasks.md): an env keeps one hidden goal (object and target positions, metaworld's
"rand_vec") for its whole life, drawn reproducibly from its seed, so an agent can infer the goal from
rewards across episodes, as in meta-RL. `resample_goal_each_episode=True` draws a new goal at every
reset instead, like the official Vintix release's wrapper.

The goal is zeroed in the observation (metaworld's `partially_observable`). Scripted demonstrators
need it: `expert_observation(obs)` puts it back. Only demonstrators may call it, never a model.
"""

from __future__ import annotations

from functools import cache
from typing import Any, Literal

import gymnasium as gym
import metaworld
import numpy as np
from metaworld.env_dict import ALL_V3_ENVIRONMENTS

DEFAULT_EPISODE_LENGTH = 100  # the paper truncates episodes at 100 steps, like JAT

GRIPPER_CENTRE_GOAL_TASKS = ("reach-v3", "reach-wall-v3")
"""Tasks whose success is the gripper centre (between the fingers) within 5 cm of the goal, while
Meta-World's scripted policy puts the hand (observation[:3]), 4.5 cm above that centre, on the goal:
the expert ends 4.2-4.7 cm from the goal, and a policy that misses the goal by 1 cm may fail."""
RenderMode = Literal["human", "rgb_array", "depth_array"]
"""The render modes metaworld's envs take."""


class MetaWorldTaskEnv(gym.Env):
    """One Meta-World task with a hidden goal, as a standard gymnasium env."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 80}

    def __init__(
        self,
        task_name: str,
        seed: int | None = None,
        episode_length: int = DEFAULT_EPISODE_LENGTH,
        resample_goal_each_episode: bool = False,
        render_mode: RenderMode | None = None,
    ) -> None:
        self.task_name = task_name
        self.resample_goal_each_episode = resample_goal_each_episode
        self.render_mode = render_mode
        self._sawyer = ALL_V3_ENVIRONMENTS[task_name](render_mode=render_mode)
        self._sawyer._partially_observable = True
        self._sawyer.__dict__.pop("sawyer_observation_space", None)  # cached before we hid the goal
        self._sawyer._set_task_called = True
        # The sawyer env raises past max_path_length and flags truncation at it: make it our length.
        self._sawyer.max_path_length = episode_length
        self.observation_space = self._sawyer.observation_space
        self.action_space = self._sawyer.action_space
        self._ml1_task: metaworld.Task | None = None
        """ML1's test goal that `use_ml1_test_goal` put in place of the seed's"""
        self._seed_and_draw_goal(seed)

    def _seed_and_draw_goal(self, seed: int | None) -> None:
        if seed is None:
            seed = int(np.random.SeedSequence().generate_state(1)[0])
        self._sawyer.seed(seed)
        if self._ml1_task is None:
            self._draw_goal()
        else:
            self._sawyer.set_task(self._ml1_task)

    def _draw_goal(self) -> None:
        """Draw a goal from the sawyer env's own seeded RNG, then freeze it.

        Metaworld's resets redraw until object and goal are far enough apart, so the draw goes
        through a real reset (the way metaworld builds its own benchmark tasks) rather than a
        hand-rolled sample that could violate those constraints.
        """
        self._sawyer._freeze_rand_vec = False
        self._sawyer.seeded_rand_vec = True  # use the env's np_random, not NumPy's global RNG
        self._sawyer.reset()
        self._sawyer._freeze_rand_vec = True

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """`seed` re-seeds the env and draws the goal anew, exactly as a new env with that seed would (an ML1 test
        goal stays)."""
        super().reset(seed=seed)
        if seed is not None:
            self._seed_and_draw_goal(seed)
        elif self.resample_goal_each_episode and self._ml1_task is None:
            self._draw_goal()
        obs, info = self._sawyer.reset()
        return obs, info

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        obs, reward, terminated, truncated, info = self._sawyer.step(action)
        return obs, float(reward), terminated, truncated, info

    # What a goal-inferring demonstrator may use (never a model): the prior over goals, the reward the
    # current state would earn under other goals, and the true goal.

    def goal_box(self) -> tuple[np.ndarray, np.ndarray]:
        """The bounds of the task's goal space (for tasks whose hidden goal is drawn at random, e.g.
        reach-v3 and push-v3, the box the env draws it from)."""
        space = self._sawyer.goal_space
        assert space is not None, f"{self.task_name}: metaworld gave the task no goal space"  # every v3 task has one
        return np.array(space.low, dtype=np.float64), np.array(space.high, dtype=np.float64)

    def goal_prior(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """`count` goals drawn uniformly from `goal_box`."""
        low, high = self.goal_box()
        return rng.uniform(low, high, size=(count, len(low)))

    def rewards_under_goals(self, goals: np.ndarray, action: np.ndarray) -> np.ndarray:
        """The reward the last step (`action`, into the current state) would have earned had the hidden
        goal been each of `goals` ``[n, 3]``: the task's own reward function, with its goal swapped."""
        sawyer, true_goal = self._sawyer, self._sawyer._target_pos
        obs = sawyer._last_stable_obs
        try:
            rewards = []
            for goal in goals:
                sawyer._target_pos = goal
                # Every v3 task's env class defines compute_reward; their base class SawyerXYZEnv, the type
                # metaworld's ALL_V3_ENVIRONMENTS declares, does not.
                rewards.append(sawyer.compute_reward(action, obs)[0])  # type: ignore[attr-defined]
        finally:
            sawyer._target_pos = true_goal
        return np.asarray(rewards, dtype=np.float64)

    def use_ml1_test_goal(self, index: int) -> None:
        """Hide Meta-World's ML1 meta-test goal `index` (of `ml1_test_tasks`: goals ML1's meta-training never uses)
        for the env's life instead of one drawn from a seed (a seeded reset keeps it), through metaworld's own
        `set_task`."""
        tasks = ml1_test_tasks(self.task_name)
        if not 0 <= index < len(tasks):
            raise ValueError(f"{self.task_name}: ML1 has {len(tasks)} test goals (0 to {len(tasks) - 1}), not {index}")
        self._ml1_task = tasks[index]
        self._sawyer.set_task(self._ml1_task)

    def place_goal(self, goal: np.ndarray) -> None:
        """Hide `goal` from the next reset on, keeping the object's start: the goal part of metaworld's
        rand_vec (its last 3 entries) is replaced. For checks of what the goal alone changes."""
        rand_vec = self._sawyer._last_rand_vec
        assert rand_vec is not None  # drawn in __init__
        self._sawyer._last_rand_vec = np.concatenate([rand_vec[:-3], np.asarray(goal, dtype=np.float64)])

    @property
    def true_goal(self) -> np.ndarray:
        """The hidden target position. For scripted demonstrators only."""
        return np.array(self._sawyer._target_pos, dtype=np.float64)

    def expert_observation(self, obs: np.ndarray) -> np.ndarray:
        """`obs` with the hidden goal written back into its last 3 entries, as metaworld's scripted
        policies expect. For scripted demonstrators only: a model must never see this."""
        full = np.array(obs, dtype=np.float64, copy=True)
        full[..., -3:] = self.true_goal
        return full

    def render(self) -> np.ndarray | None:
        return self._sawyer.render()

    def close(self) -> None:
        self._sawyer.close()


ML1_SEED = 0
"""The seed of `metaworld.ML1` whose test goals `use_ml1_test_goal` plays: ML1 draws its 50 train and 50 test goals
from NumPy's global generator, so a benchmark without a seed would hold other goals each time."""


@cache
def ml1_test_tasks(task_name: str) -> tuple[metaworld.Task, ...]:
    """Meta-World's ML1 meta-test goals of `task_name` (``metaworld.ML1(task_name, seed=ML1_SEED).test_tasks``)."""
    return tuple(metaworld.ML1(task_name, seed=ML1_SEED).test_tasks)


@cache
def _hand_to_gripper_centre(task_name: str) -> tuple[float, float, float]:
    env = MetaWorldTaskEnv(task_name, seed=0)
    env.reset()
    sawyer = env._sawyer
    offset = sawyer.get_endeff_pos() - sawyer.tcp_center
    env.close()
    return float(offset[0]), float(offset[1]), float(offset[2])


def hand_to_gripper_centre(task_name: str) -> np.ndarray:
    """The hand's position (observation[:3]) minus the gripper centre's (`tcp_center`, which reach's success
    measures) after a reset of `task_name`: (0.001, -0.005, 0.045) m with the fingers open. It stays within
    2 mm of that along a reach episode, whose fingers stay open; measured once per task per process."""
    return np.array(_hand_to_gripper_centre(task_name))
