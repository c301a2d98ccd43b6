"""The meta-RL locomotion benchmarks: HalfCheetah-Vel, HalfCheetah-Dir and Ant-Dir, on gymnasium's v5 bodies.

The tasks on which meta-RL measures adaptation from rewards (MAML, Finn et al., 2017; PEARL, Rakelly et al., 2019;
VariBAD, Zintgraf et al., 2020; RL² is compared on them there). Each hides one parameter of the reward, drawn from
the env's seed and kept for the env's life, never in the observation; only the rewards reveal it.

- **HalfCheetah-Vel** (``HalfCheetah-Vel-v5``): run at a target velocity drawn uniformly from [0, 3] (m/s), as
  PEARL's and VariBAD's released code draw it (``sample_tasks`` in katerakelly/oyster and lmzintgraf/varibad; their
  docstrings, copied from MAML's, say [0, 2]); MAML's own is [0, 2] (cbfinn/maml_rl ``sample_goals``);
  reward ``-|v - v_target| - 0.05 * |a|^2`` (VariBAD's and PEARL's ``forward_reward - 0.5 * 1e-1 * sum(a^2)``).
- **HalfCheetah-Dir** (``HalfCheetah-Dir-v5``): run forward or backward, the direction drawn from {-1, +1};
  reward ``direction * v - 0.05 * |a|^2``.
- **Ant-Dir** (``Ant-Dir-v5``): the forward/backward Ant-Dir that VariBAD's and PEARL's papers describe ("Ant-Fwd-
  Back"): walk along +x or -x, the direction drawn from {-1, +1}. Their released code differs from their text:
  VariBAD's ``AntDirEnv`` reads the ±1 as an angle in radians (walk at ±57° from x), PEARL's ant-dir config draws
  2 random directions in the plane;
  reward ``direction * v_x`` plus Ant-v5's own control, contact and survival terms (weights 0.5, 5e-4, 1.0, as
  VariBAD's ant), terminated when the torso leaves Ant-v5's healthy height range [0.2, 1.0] as theirs is.

Episodes are 200 steps (VariBAD's and PEARL's horizon). Where ours differ from theirs: the v5 bodies (MuJoCo 3,
gymnasium's observations: HalfCheetah's 17 entries, Ant's 105 with contact forces) instead of mujoco-py's v2/v3
ones; velocities from gymnasium's own ``x_velocity`` (the torso's x displacement over dt, as theirs compute it).
"""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.envs.mujoco.ant_v5 import AntEnv
from gymnasium.envs.mujoco.half_cheetah_v5 import HalfCheetahEnv
from gymnasium.envs.mujoco.mujoco_env import MujocoEnv

EPISODE_STEPS = 200
CHEETAH_CONTROL_WEIGHT = 0.05
"""VariBAD's and PEARL's cheetah control cost, ``0.5 * 1e-1 * sum(a^2)`` (gymnasium's default is 0.1)."""
VELOCITY_RANGE = (0.0, 3.0)


class HiddenParameterLocomotion(gym.Env):
    """A gymnasium MuJoCo body whose reward depends on a hidden parameter (`parameter`), drawn from the env's seed
    and kept for its life; subclasses say how the parameter is drawn and how it pays."""

    metadata = {"render_modes": ["human", "rgb_array", "depth_array"]}
    body: ClassVar[type[MujocoEnv]]
    body_kwargs: ClassVar[dict[str, Any]] = {}

    def __init__(self, seed: int | None = None, episode_length: int = EPISODE_STEPS,
                 resample_goal_each_episode: bool = False, render_mode: str | None = None) -> None:
        self._body = self.body(render_mode=render_mode, **self.body_kwargs)
        self.episode_length = episode_length
        self.resample_goal_each_episode = resample_goal_each_episode
        self.render_mode = render_mode
        self.observation_space = self._body.observation_space
        self.action_space = self._body.action_space
        self._steps = 0
        self._last: dict[str, Any] = {}
        self._parameter = self._draw(np.random.default_rng(seed))

    def _draw(self, rng: np.random.Generator) -> float:
        return float(self.goal_prior(rng, 1)[0, 0])

    @property
    def model(self) -> Any:
        """The MuJoCo model, so physics variations (`vintix.tasks.mujoco`) apply as to any MuJoCo task."""
        return self._body.model

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """`seed` draws the parameter anew, exactly as a new env with that seed would; otherwise it stays (or, with
        `resample_goal_each_episode`, as a goal-aware expert trains, is drawn from the env's own generator)."""
        super().reset(seed=seed)
        if seed is not None:
            self._parameter = self._draw(np.random.default_rng(seed))
        elif self.resample_goal_each_episode:
            self._parameter = self._draw(self.np_random)
        obs, info = self._body.reset(seed=int(self.np_random.integers(2**31 - 1)))
        self._steps = 0
        return obs, {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        obs, _, terminated, _, info = self._body.step(action)
        self._steps += 1
        self._last = info
        reward = float(self.rewards_under_goals(np.array([[self._parameter]]), action)[0])
        return obs, reward, terminated, self._steps >= self.episode_length, info

    # What a goal-inferring demonstrator may use (never a model): the prior, the reward of the last step under
    # other parameters, and the true parameter.

    def goal_box(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def goal_prior(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """`count` parameters ``[count, 1]`` drawn as the env draws its own."""
        raise NotImplementedError

    def rewards_under_goals(self, goals: np.ndarray, action: np.ndarray) -> np.ndarray:
        """The reward of the last step had the parameter been each of `goals` ``[n, 1]``."""
        raise NotImplementedError

    @property
    def true_goal(self) -> np.ndarray:
        """The hidden parameter ``[1]``. For demonstrators only."""
        return np.array([self._parameter])

    def render(self) -> Any:
        return self._body.render()

    def close(self) -> None:
        self._body.close()


def with_goal_observed(env: gym.Env) -> gym.Env:
    """`env` (a `HiddenParameterLocomotion` under any wrappers) observed with its hidden parameter appended: what
    a goal-aware expert trains and acts on, never what a model sees."""
    inner = env.unwrapped
    if not isinstance(inner, HiddenParameterLocomotion):
        raise TypeError(f"{inner} hides no parameter: only the meta-RL locomotion tasks have one to observe")
    space, (low, high) = env.observation_space, inner.goal_box()
    assert isinstance(space, gym.spaces.Box)  # the MuJoCo bodies' observations
    observed = gym.spaces.Box(np.append(space.low, low), np.append(space.high, high), dtype=np.float64)
    return gym.wrappers.TransformObservation(env, lambda obs: np.append(obs, inner.true_goal), observed)


class HalfCheetahVelEnv(HiddenParameterLocomotion):
    """HalfCheetah at a hidden target velocity."""

    body = HalfCheetahEnv
    body_kwargs = {"ctrl_cost_weight": CHEETAH_CONTROL_WEIGHT}

    def goal_box(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array([VELOCITY_RANGE[0]]), np.array([VELOCITY_RANGE[1]])

    def goal_prior(self, rng: np.random.Generator, count: int) -> np.ndarray:
        return rng.uniform(*VELOCITY_RANGE, size=(count, 1))

    def rewards_under_goals(self, goals: np.ndarray, action: np.ndarray) -> np.ndarray:
        return -np.abs(self._last["x_velocity"] - goals[:, 0]) + self._last["reward_ctrl"]


class DirectionEnv(HiddenParameterLocomotion):
    """A body that must run along a hidden direction of the x axis, -1 or +1."""

    def goal_box(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array([-1.0]), np.array([1.0])

    def goal_prior(self, rng: np.random.Generator, count: int) -> np.ndarray:
        return rng.choice([-1.0, 1.0], size=(count, 1))

    def _other_terms(self) -> float:
        return float(self._last["reward_ctrl"])

    def rewards_under_goals(self, goals: np.ndarray, action: np.ndarray) -> np.ndarray:
        return goals[:, 0] * self._last["x_velocity"] + self._other_terms()


class HalfCheetahDirEnv(DirectionEnv):
    """HalfCheetah running forward or backward."""

    body = HalfCheetahEnv
    body_kwargs = {"ctrl_cost_weight": CHEETAH_CONTROL_WEIGHT}


class AntDirEnv(DirectionEnv):
    """Ant walking forward or backward along x."""

    body = AntEnv

    def _other_terms(self) -> float:
        return float(self._last["reward_ctrl"] + self._last["reward_contact"] + self._last["reward_survive"])

