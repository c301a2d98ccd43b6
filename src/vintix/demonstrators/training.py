"""Training demonstrators with Stable-Baselines3, one recipe per encoder group.

The paper imitated JAT's MuJoCo experts and trained PPO for Industrial Benchmark; no registry serves
JAT's agents, so MuJoCo demonstrators are trained here from scratch. Each recipe picks what reaches a
good score fastest on a CPU: PPO for the pendulum and Swimmer (cheap env steps, on-policy is fine),
SAC elsewhere (sample-efficient where env steps are costly). Hyperparameters follow the RL Baselines3
Zoo where it has tuned ones; budgets are set for a laptop and recorded beside each shipped policy.

Industrial Benchmark follows the paper (PPO, advantage normalization, target KL 0.2, batch 50,
gamma 0.97, 1M steps, trained on the delta reward and scored on the classic one) with one change: a
single policy is trained on all 21 setpoints at once, one env each (the setpoint is its first
observation), with 250 steps per env per rollout (5,250 per update, the paper's 2,500 per task).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import gymnasium as gym
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from vintix.demonstrators.trained import ALGORITHMS, save_trained_policy, shipped_weights_dir
from vintix.errors import VintixError
from vintix.tasks import get_task, list_tasks, make_env


@dataclass(frozen=True)
class DemonstratorRecipe:
    """How to train the demonstrator of one encoder group."""

    algorithm: str
    """'PPO', 'SAC' or 'TD3' (Stable-Baselines3)."""
    timesteps: int
    """Env steps to train for, over all envs together."""
    hyperparameters: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments of the SB3 algorithm (gamma, batch_size, ...)."""
    train_tasks: tuple[str, ...] = ()
    """Tasks trained on, one env each; empty: the group's single task."""
    normalize_observations: bool = False
    """Train behind VecNormalize (its statistics ship with the weights)."""
    env_options: dict[str, Any] = field(default_factory=dict)
    """Options for `make_env` during training only (evaluation uses the task as registered)."""


_IB_SETPOINTS = tuple(t.name for t in list_tasks(domain="industrial_benchmark"))

RECIPES: dict[str, DemonstratorRecipe] = {
    "mujoco-invertedpendulum": DemonstratorRecipe("PPO", 50_000),
    "mujoco-inverteddoublependulum": DemonstratorRecipe("SAC", 50_000),
    "mujoco-reacher": DemonstratorRecipe("SAC", 30_000),
    "mujoco-swimmer": DemonstratorRecipe("PPO", 300_000, {"gamma": 0.9999}, normalize_observations=True),
    "mujoco-pusher": DemonstratorRecipe("SAC", 60_000),
    "mujoco-hopper": DemonstratorRecipe("SAC", 300_000),
    "mujoco-halfcheetah": DemonstratorRecipe("SAC", 500_000),
    "mujoco-walker2d": DemonstratorRecipe("SAC", 500_000),
    "mujoco-ant": DemonstratorRecipe("SAC", 1_000_000),
    "mujoco-humanoid": DemonstratorRecipe("SAC", 1_000_000),
    "mujoco-humanoidstandup": DemonstratorRecipe("SAC", 1_000_000),
    "industrial_benchmark": DemonstratorRecipe(
        "PPO", 1_000_000,
        {"gamma": 0.97, "n_steps": 250, "batch_size": 50, "target_kl": 0.2, "normalize_advantage": True},
        train_tasks=_IB_SETPOINTS, normalize_observations=True, env_options={"reward_type": "delta"},
    ),
}


def recipe_for(task: str) -> DemonstratorRecipe:
    """The training recipe of a task's group; Meta-World and Bi-DexHands have none."""
    spec = get_task(task)
    if spec.group not in RECIPES:
        reason = ("its demonstrators are metaworld's scripted policies, nothing to train"
                  if spec.domain == "metaworld" else "no recipe for this domain")
        raise VintixError(f"cannot train a demonstrator for {spec.name!r}: {reason}")
    return RECIPES[spec.group]


def _monitored_env(task: str, options: dict[str, Any]) -> gym.Env:
    return Monitor(make_env(task, **options))


def train_demonstrator(task: str, timesteps: int | None = None, seed: int = 0, out: Path | None = None,
                       progress_bar: bool = True, recipe: DemonstratorRecipe | None = None) -> Path:
    """Train the demonstrator of `task`'s group and save it (default: into the package).

    Returns the weights file. `timesteps` overrides the budget (e.g. for a quick check); `recipe`
    replaces the group's recipe (to try other hyperparameters).
    """
    spec = get_task(task)
    recipe = recipe or recipe_for(task)
    budget = timesteps or recipe.timesteps
    tasks = recipe.train_tasks or (spec.name,)
    venv = DummyVecEnv([partial(_monitored_env, name, recipe.env_options) for name in tasks])
    vec_normalize = None
    if recipe.normalize_observations:
        gamma = recipe.hyperparameters.get("gamma", 0.99)
        venv = vec_normalize = VecNormalize(venv, norm_obs=True, norm_reward=False, gamma=gamma)
    model = ALGORITHMS[recipe.algorithm]("MlpPolicy", venv, seed=seed, device="cpu", verbose=0,
                                         **recipe.hyperparameters)
    # A logger without outputs: SB3's default one makes an empty SB3-<time> folder in /tmp every run.
    model.set_logger(Logger(folder=None, output_formats=[]))
    start = time.perf_counter()
    model.learn(total_timesteps=budget, progress_bar=progress_bar)
    seconds = time.perf_counter() - start
    command = f"vintix demonstrator train --task {spec.name} --seed {seed}"
    if timesteps:
        command += f" --timesteps {timesteps}"
    info = {"group": spec.group, "train_tasks": list(tasks), "timesteps": budget, "seed": seed,
            "train_seconds": round(seconds, 1), "hyperparameters": recipe.hyperparameters,
            "env_options": recipe.env_options, "command": command}
    path = save_trained_policy(model, vec_normalize, spec.group, out or shipped_weights_dir(), info)
    venv.close()
    return path
