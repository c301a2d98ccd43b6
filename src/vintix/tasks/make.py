"""`make_env`: one entry point that returns a standard gymnasium env for any task of the registry.

Meta-World and Industrial Benchmark tasks are registered with gymnasium under the `vintix/`
namespace, so `gymnasium.make("vintix/pick-place-v3")` works too once `vintix` is imported; MuJoCo
tasks are gymnasium's own ids.
"""

from __future__ import annotations

import inspect
import warnings
from collections.abc import Callable
from functools import cache
from typing import Any

import gymnasium as gym
import numpy as np

from vintix.errors import MissingDependencyError, UnsupportedOptionError, VintixError
from vintix.tasks.registry import HIDDEN_GOAL_MUJOCO_TASKS, META_RL_TASKS, TaskSpec, builtin_tasks, get_task

NAMESPACE = "vintix"
ENV_CLASSES = {"HalfCheetah-Vel-v5": "HalfCheetahVelEnv", "HalfCheetah-Dir-v5": "HalfCheetahDirEnv",
               "Ant-Dir-v5": "AntDirEnv"}
"""The meta-RL tasks' env classes in `vintix.tasks.meta_mujoco` (imported only when one is made)."""


def gymnasium_id(spec: TaskSpec) -> str:
    """The id under which gymnasium knows the task."""
    gymnasiums_own = spec.domain == "mujoco" and spec.name not in HIDDEN_GOAL_MUJOCO_TASKS
    return spec.name if gymnasiums_own else f"{NAMESPACE}/{spec.name}"


def register_gymnasium_envs() -> None:
    """Register the Meta-World, Industrial Benchmark, discrete-benchmark and hidden-goal MuJoCo tasks with gymnasium
    (idempotent). Runs when `vintix.tasks` is imported, so it reads the package's own tasks only: task plug-ins,
    which may import vintix themselves, load at the first lookup."""
    for spec in builtin_tasks("metaworld"):
        if gymnasium_id(spec) not in gym.registry:
            gym.register(
                gymnasium_id(spec),
                entry_point="vintix.tasks.metaworld:MetaWorldTaskEnv",
                kwargs={"task_name": spec.name},
                max_episode_steps=spec.episode_length,
            )
    for spec in builtin_tasks("industrial_benchmark"):
        if gymnasium_id(spec) not in gym.registry:
            gym.register(
                gymnasium_id(spec),
                entry_point="vintix.tasks.industrial_benchmark:IndustrialBenchmarkEnv",
                kwargs={"setpoint": float(spec.name.split("-")[2])},
                max_episode_steps=spec.episode_length,
            )
    for spec in builtin_tasks("icrl"):
        if gymnasium_id(spec) not in gym.registry:
            gym.register(gymnasium_id(spec), entry_point="vintix.tasks.discrete_benchmarks:icrl_env",
                         kwargs={"name": spec.name}, max_episode_steps=spec.episode_length)
    for spec in builtin_tasks("mujoco"):
        if spec.name in HIDDEN_GOAL_MUJOCO_TASKS and gymnasium_id(spec) not in gym.registry:
            entry_point = ("vintix.tasks.reacher_hidden:ReacherHiddenEnv" if spec.name == "Reacher-hidden-v5" else
                           f"vintix.tasks.meta_mujoco:{ENV_CLASSES[spec.name]}")
            gym.register(gymnasium_id(spec), entry_point=entry_point, kwargs={"episode_length": spec.episode_length},
                         max_episode_steps=spec.episode_length)


class SeedFirstReset(gym.Wrapper):
    """Makes `make_env(task, seed=s)` reproducible: the first `reset()` without a seed uses `s`, and
    the action space is seeded with `s` so `action_space.sample()` is reproducible too."""

    def __init__(self, env: gym.Env, seed: int | None) -> None:
        super().__init__(env)
        self._first_seed = seed
        if seed is not None:
            env.action_space.seed(seed)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        if seed is None:
            seed = self._first_seed
        self._first_seed = None
        return self.env.reset(seed=seed, options=options)


def _make_mujoco(spec: TaskSpec, seed: int | None, viscosity: float | None = None,
                 gravity_scale: float | None = None, render_mode: str | None = None,
                 resample_goal_each_episode: bool = False) -> gym.Env:
    from vintix.tasks.mujoco import make_mujoco_env

    # A hidden-goal task draws its hidden target from the seed it is made with, as Meta-World's do.
    hidden_goal: dict[str, Any] = {"seed": seed} if spec.name in HIDDEN_GOAL_MUJOCO_TASKS else {}
    if resample_goal_each_episode:
        if spec.name not in META_RL_TASKS:
            raise UnsupportedOptionError(f"{spec.name!r} has no hidden parameter to redraw each episode; "
                                         f"resample_goal_each_episode is for {', '.join(META_RL_TASKS)}")
        hidden_goal["resample_goal_each_episode"] = True
    return make_mujoco_env(gymnasium_id(spec), viscosity=viscosity, gravity_scale=gravity_scale,
                           render_mode=render_mode, **hidden_goal)


def _make_metaworld(spec: TaskSpec, seed: int | None, episode_length: int | None = None,
                    resample_goal_each_episode: bool = False, render_mode: str | None = None) -> gym.Env:
    length = episode_length or spec.episode_length
    with warnings.catch_warnings():
        # The hidden goal is a Box with equal bounds (always 0) by design; gymnasium's env checker
        # warns about it on every make, which would bury a command's own output.
        warnings.filterwarnings("ignore", message=".*maximum and minimum values are equal.*")
        return gym.make(gymnasium_id(spec), seed=seed, episode_length=length, max_episode_steps=length,
                        resample_goal_each_episode=resample_goal_each_episode, render_mode=render_mode)


def _make_industrial_benchmark(spec: TaskSpec, seed: int | None, reward_type: str = "classic") -> gym.Env:
    return gym.make(gymnasium_id(spec), reward_type=reward_type)


def _make_bidexhands(spec: TaskSpec, seed: int | None) -> gym.Env:
    try:
        import isaacgym  # noqa: F401
    except ImportError as error:
        raise MissingDependencyError(
            f"Bi-DexHands task {spec.name!r} runs on NVIDIA IsaacGym (Preview 4: Linux, an NVIDIA GPU), which "
            "no package registry serves: download it from NVIDIA's developer site, `pip install -e "
            "isaacgym/python`, then install Bi-DexHands (PKU-MARL/DexterousHands). Without it, this task's "
            "data can still be read, validated and trained on."
        ) from error
    raise NotImplementedError(
        f"IsaacGym is installed, but vintix has no Bi-DexHands env wrapper yet for {spec.name!r}: "
        "no machine of this project has IsaacGym to build and test one against."
    )


def _make_toy(spec: TaskSpec, seed: int | None) -> gym.Env:
    from vintix.tasks.toy import PointGoalEnv

    return gym.wrappers.TimeLimit(PointGoalEnv(seed), spec.episode_length)


def _make_icrl(spec: TaskSpec, seed: int | None) -> gym.Env:
    return gym.make(gymnasium_id(spec), seed=seed)


def _make_custom(spec: TaskSpec, seed: int | None, **env_kwargs: Any) -> gym.Env:
    from vintix.tasks.custom import make_custom_env

    return make_custom_env(spec, **env_kwargs)


_FACTORIES: dict[str, Callable[..., gym.Env]] = {
    "mujoco": _make_mujoco,
    "metaworld": _make_metaworld,
    "industrial_benchmark": _make_industrial_benchmark,
    "bidexhands": _make_bidexhands,
    "toy": _make_toy,
    "icrl": _make_icrl,
    "custom": _make_custom,
}


def domain_options(domain: str) -> list[str]:
    """The keyword options `make_env` accepts for tasks of `domain` (custom tasks: their env's own)."""
    return [name for name, p in inspect.signature(_FACTORIES[domain]).parameters.items()
            if p.kind is not inspect.Parameter.VAR_KEYWORD][2:]


def make_env(task: str, seed: int | None = None, **options: Any) -> gym.Env:
    """A gymnasium env for `task` (a name or alias from the registry).

    Options by domain: MuJoCo `viscosity`, `gravity_scale`, `render_mode`; Meta-World
    `episode_length`, `resample_goal_each_episode`, `render_mode`; Industrial Benchmark `reward_type`.
    An option the task's domain does not have is an error, never silently ignored.
    """
    spec = get_task(task)
    accepted = domain_options(spec.domain)
    unknown = sorted(set(options) - set(accepted))
    if unknown and spec.domain != "custom":  # a custom env's factory or gymnasium id takes its own options
        where = [d for d in _FACTORIES if set(unknown) <= set(domain_options(d))]
        hint = f" It exists for {', '.join(where)} tasks." if where else ""
        raise UnsupportedOptionError(
            f"option(s) {', '.join(unknown)} do not apply to {spec.domain} task {spec.name!r}; "
            f"it accepts: {', '.join(accepted) or 'no options'}.{hint}"
        )
    return SeedFirstReset(_FACTORIES[spec.domain](spec, seed, **options), seed)


ActionSpace = gym.spaces.Box | gym.spaces.Discrete


class ActionSpaceError(VintixError, TypeError):
    """An action space vintix cannot act in (not a bounded Box or a Discrete starting at 0), or of another kind than
    the task's."""


def action_space_problem(space: gym.Space) -> str | None:
    """Why vintix cannot act in `space`, or None: it acts in a Box (bounded, for the collector's uniform noise) or a
    Discrete of actions 0 to n - 1. MultiDiscrete, Tuple and the rest are refused: say so, with the way round."""
    if isinstance(space, gym.spaces.Discrete):
        if int(space.start) != 0:
            return (f"{space} starts at {int(space.start)}; vintix's discrete actions are 0 to n - 1 (they index the "
                    "model's logits): wrap the env to shift its actions (gymnasium.ActionWrapper) to Discrete(n)")
        return None
    if isinstance(space, gym.spaces.Box):
        return None
    if isinstance(space, gym.spaces.MultiDiscrete):
        return (f"{space} is MultiDiscrete, which vintix does not support: flatten it into one Discrete of "
                f"{int(np.prod(space.nvec))} actions (a gymnasium.ActionWrapper), or make each part a task of its own")
    return f"{space} is neither a Box nor a Discrete action space, the two kinds vintix acts in"


def action_space_of(space: gym.Space, discrete: bool | None = None) -> ActionSpace:
    """`space` as the Box or Discrete it is (gymnasium's envs and SB3's policies type their action space as any
    `Space`); an ActionSpaceError for any other space, and, given `discrete`, for a space of the other kind."""
    problem = action_space_problem(space)
    if problem is not None:
        raise ActionSpaceError(problem)
    if discrete is not None and isinstance(space, gym.spaces.Discrete) != discrete:
        want = "a Discrete" if discrete else "a Box"
        raise ActionSpaceError(f"expected {want} action space, got {space}: a model's group acts in one kind of space "
                               "(a discrete group's head gives logits, a continuous one's gives actions)")
    return space  # type: ignore[return-value]


def action_box(space: gym.Space) -> gym.spaces.Box:
    """`space` as the Box it is, for code that only continuous control reaches (the noise mixed into a Box action,
    SB3's continuous demonstrators); a Discrete or other space is an ActionSpaceError."""
    return action_space_of(space, discrete=False)  # type: ignore[return-value]


@cache
def task_action_space(task: str) -> ActionSpace:
    """The action space of `task`'s env, read off one env (seeds and variations leave it alone)."""
    env = make_env(task)
    try:
        return action_space_of(env.action_space)
    finally:
        env.close()
