"""What a demonstrator is to the collector: a batched policy over a set of envs of one task."""

from __future__ import annotations

import importlib
import os
import stat
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Protocol, cast

import gymnasium as gym
import numpy as np

from vintix.errors import MissingDependencyError, VintixError, call_plugin
from vintix.tasks import TaskSpec, get_task
from vintix.tasks.registry import HIDDEN_GOAL_MUJOCO_TASKS, META_RL_TASKS


class Demonstrator(Protocol):
    """An expert policy, evaluated on a batch of envs at once."""

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        """Actions [n_envs, act_dim] for observations [n_envs, obs_dim] of `envs` (deterministic)."""
        ...


BEHAVIOURS = ("expert", "posterior-sampling", "probing", "probe-then-sample", "learner", "posterior-search",
              "walk-search")
"""How a demonstrator plays a history: as the goal-aware expert, or without the goal, inferring it from
rewards (`vintix.demonstrators.posterior`): aiming each episode at a goal drawn from its posterior;
probing the goal box's corners in the first episode and aiming later ones at the likeliest goal; or
probing, then aiming later ones at goals drawn from the posterior (its target: the probe, then the expert);
'posterior-search': the goals not ruled out, searched in a fixed order across episodes, for sparse rewards (on the
discrete benchmarks, `vintix.demonstrators.discrete_benchmarks`, the cells along a spiral); 'walk-search' (their
rooms only): a random walk until a reward shows the goal. 'learner' (the discrete benchmarks only): an RL algorithm
learning from scratch, AD's own histories."""
PROBING_BEHAVIOURS = ("probing", "probe-then-sample")
"""The behaviours whose first episode probes the goal box (and so take a `probe_margin`)."""
AIMS = ("hand", "gripper-centre")
"""What a Meta-World scripted expert puts on the goal: the hand, as Meta-World's policies do, or, on the
tasks of `vintix.tasks.metaworld.GRIPPER_CENTRE_GOAL_TASKS`, the gripper centre whose distance their success
measures (5 cm of slack around the goal instead of under 1 cm)."""


def expert_name(spec: TaskSpec) -> str:
    """The name a task's trained demonstrator is stored and trained under: its encoder group (one policy serves
    the group's tasks), or, for a meta-RL task, whose expert observes its hidden parameter, the task's own
    (``HalfCheetah-Vel-v5``: ``halfcheetah-vel``)."""
    return spec.name.removesuffix("-v5").lower() if goal_observed(spec) else spec.group


def goal_observed(spec: TaskSpec) -> bool:
    """Whether `spec`'s expert observes its hidden parameter (the meta-RL tasks' goal-aware experts)."""
    return spec.name in META_RL_TASKS


def load_demonstrator(task: str, weights: Path | None = None, behaviour: str = "expert",
                      source: str | None = None, probe_margin: float = 0.0, aim: str = "hand",
                      lapse_probability: float = 0.0, reward_tolerance: float = 0.0) -> Demonstrator:
    """The project's demonstrator for `task`: Meta-World's scripted expert, or the trained policy
    shipped for the task's group (or the one in `weights`, a folder of trained weights); a clear error for
    tasks that have none. A `behaviour` other than "expert" wraps a scripted expert of a hidden-goal task
    (Meta-World, toy, Reacher-hidden-v5) in a demonstrator that does not see the goal and infers it from rewards.
    `source`: a demonstrator from outside the package instead (`external_demonstrator`). `probe_margin`: with
    behaviour 'probing' or 'probe-then-sample', how far outside the goal box the probe's corners lie. `aim`: what
    a scripted reach expert puts on the goal (`AIMS`), whatever the behaviour. `lapse_probability`: with behaviour
    'probe-then-sample', the chance of a lapse in an episode after the first aimed one
    (`vintix.demonstrators.posterior.PosteriorSettings.lapse_probability`). `reward_tolerance`: with a behaviour
    other than "expert", the std of the reward likelihood (0: the behaviour's default;
    `vintix.demonstrators.posterior.PosteriorSettings.reward_tolerance`)."""
    spec = get_task(task)
    if (probe_margin and behaviour not in PROBING_BEHAVIOURS) or probe_margin < 0:
        raise VintixError(f"{spec.name!r}: probe_margin {probe_margin} (with behaviour {behaviour!r}) must be >= 0 and "
                          f"is for a behaviour whose first episode probes ({' or '.join(PROBING_BEHAVIOURS)}); "
                          "leave it out otherwise")
    check_aim(spec.name, aim)
    if (lapse_probability and behaviour != "probe-then-sample") or not 0 <= lapse_probability <= 1:
        raise VintixError(f"{spec.name!r}: lapse_probability {lapse_probability} (with behaviour {behaviour!r}) must "
                          "lie in [0, 1] and is for behaviour 'probe-then-sample'; leave it out otherwise")
    if (reward_tolerance and behaviour == "expert") or reward_tolerance < 0:
        raise VintixError(f"{spec.name!r}: reward_tolerance {reward_tolerance} (with behaviour {behaviour!r}) must be "
                          "> 0 and is for a behaviour that infers the goal from rewards; leave it out otherwise")
    if source is not None:
        if behaviour != "expert" or weights is not None or aim != "hand":
            raise VintixError(f"{spec.name!r}: a demonstrator named by the recipe ({source!r}) plays as it is: "
                              "leave out behaviour, weights and aim")
        return external_demonstrator(spec.name, source)
    kind = expert_kind(spec)
    if kind == "custom":
        return _no_expert_of_your_own(spec, weights, aim)
    if behaviour not in BEHAVIOURS:
        raise VintixError(f"unknown demonstrator behaviour {behaviour!r}; choose one of {', '.join(BEHAVIOURS)}")
    if kind == "discrete":
        return _discrete_demonstrator(spec, behaviour, weights, aim, reward_tolerance)
    if behaviour in ("learner", "walk-search"):
        raise VintixError(f"{spec.name!r}: behaviour {behaviour!r} exists for the discrete benchmarks (domain icrl: "
                          "Dark Room, Key-to-Door, the bandit); choose another")
    if behaviour != "expert":
        return _goal_inferring(spec, behaviour, weights, probe_margin, aim, lapse_probability, reward_tolerance)
    return GOAL_AWARE_EXPERTS[kind](spec, weights, aim)


def expert_kind(spec: TaskSpec) -> str:
    """Which row of `GOAL_AWARE_EXPERTS` makes `spec`'s goal-aware expert ('custom' and 'discrete' aside: a task of
    your own names its demonstrator, the discrete benchmarks' play as `vintix.demonstrators.discrete_benchmarks`
    says)."""
    if spec.domain in ("custom", "metaworld", "toy", "bidexhands"):
        return spec.domain
    if spec.domain == "icrl":
        return "discrete"
    if spec.name in HIDDEN_GOAL_MUJOCO_TASKS and not goal_observed(spec):
        return "reacher-hidden"
    return "trained"


def _no_expert_of_your_own(spec: TaskSpec, weights: Path | None, aim: str) -> Demonstrator:
    raise VintixError(f"task {spec.name!r} is your own, and the package has no demonstrator for it: name one in "
                      "the recipe, demonstrator: module:callable (your Demonstrator) or sb3:ALGO:PATH.zip "
                      "(a trained Stable-Baselines3 or sbx:ALGO:PATH.zip model)")


def _scripted_metaworld(spec: TaskSpec, weights: Path | None, aim: str) -> Demonstrator:
    _no_weights(spec, weights, "Meta-World's experts are scripted")
    from vintix.demonstrators.scripted import ScriptedMetaWorldDemonstrator

    return ScriptedMetaWorldDemonstrator(spec.name, aim)


def _scripted_point_goal(spec: TaskSpec, weights: Path | None, aim: str) -> Demonstrator:
    _no_weights(spec, weights, "the toy task's expert is scripted")
    from vintix.demonstrators.scripted import ScriptedPointGoalDemonstrator

    return ScriptedPointGoalDemonstrator()


def _scripted_reacher(spec: TaskSpec, weights: Path | None, aim: str) -> Demonstrator:
    _no_weights(spec, weights, "its expert is scripted (inverse kinematics)")
    from vintix.demonstrators.scripted import ScriptedReacherDemonstrator

    return ScriptedReacherDemonstrator()


def _no_isaacgym(spec: TaskSpec, weights: Path | None, aim: str) -> Demonstrator:
    _no_weights(spec, weights, "Bi-DexHands' experts need IsaacGym")
    raise VintixError(f"no demonstrator for Bi-DexHands task {spec.name!r}: its envs need IsaacGym")


def _trained(spec: TaskSpec, weights: Path | None, aim: str) -> Demonstrator:
    from vintix.demonstrators.trained import TrainedDemonstrator

    return TrainedDemonstrator(spec, weights)


def _no_weights(spec: TaskSpec, weights: Path | None, why: str) -> None:
    if weights is not None:
        raise VintixError(f"{spec.name!r} has no trained demonstrator to load from {weights}: {why}; leave the "
                          "weights out")


GOAL_AWARE_EXPERTS: dict[str, Callable[[TaskSpec, Path | None, str], Demonstrator]] = {
    "metaworld": _scripted_metaworld,
    "toy": _scripted_point_goal,
    "reacher-hidden": _scripted_reacher,
    "bidexhands": _no_isaacgym,
    "trained": _trained,
}
"""How each kind of task (`expert_kind`) gets the expert that sees its goal: (task, trained weights or None,
aim) -> the demonstrator. MuJoCo and Industrial Benchmark tasks load the trained policy shipped for their group."""


def _discrete_demonstrator(spec: TaskSpec, behaviour: str, weights: Path | None, aim: str,
                           reward_tolerance: float) -> Demonstrator:
    from vintix.demonstrators.discrete_benchmarks import ICRL_BEHAVIOURS, icrl_demonstrator

    if behaviour not in ICRL_BEHAVIOURS or weights is not None or aim != "hand" or reward_tolerance:
        raise VintixError(f"{spec.name!r} is a discrete benchmark: its demonstrators play as "
                          f"{', '.join(ICRL_BEHAVIOURS)} (vintix.demonstrators.discrete_benchmarks) and take no "
                          f"weights, aim or reward_tolerance; got behaviour {behaviour!r}")
    if behaviour in ("posterior-search", "walk-search") and spec.group == "bernoulli-bandit":
        raise VintixError(f"{spec.name!r}: {behaviour} walks a room's cells; on a bandit use "
                          "posterior-sampling (Thompson sampling)")
    return icrl_demonstrator(behaviour)


def _goal_inferring(spec: TaskSpec, behaviour: str, weights: Path | None, probe_margin: float, aim: str,
                    lapse_probability: float, reward_tolerance: float) -> Demonstrator:
    """The goal-aware expert wrapped in a demonstrator that does not see the goal and infers it from rewards."""
    from vintix.demonstrators.posterior import DEFAULT_SETTINGS, PosteriorSamplingDemonstrator, posterior_settings

    key = expert_name(spec)
    # Trained weights aim only where the expert observes the goal (a meta-RL task's goal-aware expert).
    if key not in DEFAULT_SETTINGS or (weights is not None and not goal_observed(spec)):
        raise VintixError(f"{spec.name!r}: {behaviour} needs a hidden-goal task with an expert that can aim at a "
                          f"given goal (tasks of {', '.join(sorted(DEFAULT_SETTINGS))}), not a {spec.group} "
                          f"task{' or trained weights' if weights is not None else ''}; use behaviour 'expert'")
    expert = load_demonstrator(spec.name, weights, aim=aim)
    settings = posterior_settings(key, behaviour, probe_margin, lapse_probability, reward_tolerance)
    return PosteriorSamplingDemonstrator(expert, settings)  # type: ignore[arg-type]


def check_aim(task: str, aim: str) -> None:
    """Raise unless a scripted expert of `task` can put `aim` (one of `AIMS`) on the goal."""
    if aim == "hand":
        return
    if aim not in AIMS:
        raise VintixError(f"{task!r}: unknown aim {aim!r}; choose one of {', '.join(AIMS)}")
    from vintix.tasks.metaworld import GRIPPER_CENTRE_GOAL_TASKS

    if task not in GRIPPER_CENTRE_GOAL_TASKS:
        raise VintixError(f"{task!r}: aim {aim!r} is for the package's scripted experts of "
                          f"{', '.join(GRIPPER_CENTRE_GOAL_TASKS)}, whose success measures the gripper centre; "
                          "leave aim out otherwise")


class ModelFileDemonstrator:
    """A trained Stable-Baselines3 (or sbx) model as a demonstrator: its deterministic action."""

    def __init__(self, model: Any) -> None:
        self.model = model

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        return np.asarray(self.model.predict(observations, deterministic=True)[0])


_MODEL_LIBRARIES = {"sb3": "stable_baselines3", "sbx": "sbx"}


def external_demonstrator(task: str, source: str) -> Demonstrator:
    """A demonstrator from outside the package, as a recipe names it (``demonstrator:``):

    - ``module:callable``: called with the task name, returns a `Demonstrator` (a class whose ``__init__``
      takes the task name will do);
    - ``sb3:ALGO:PATH`` or ``sbx:ALGO:PATH``: a model saved by Stable-Baselines3 or sbx (``model.save``),
      loaded by that library's ``ALGO.load``. Such a file is unpickled, which runs any code in it: vintix
      loads it only when it is yours and nobody else can write it, and you must trust where it came from;
    - ``weights:DIR``: a folder of weights ``vintix demonstrator train`` wrote (weights-only safetensors),
      instead of the shipped ones.
    """
    library, _, rest = source.partition(":")
    if library == "weights":
        return load_demonstrator(task, weights=Path(rest).expanduser())
    if library in _MODEL_LIBRARIES:
        algorithm, _, path = rest.partition(":")
        if not algorithm or not path:
            raise VintixError(f"demonstrator {source!r}: a model file reads {library}:ALGO:PATH, e.g. {library}:SAC:"
                              "runs/pendulum/model.zip")
        refuse_untrusted(Path(path))
        try:
            module = importlib.import_module(_MODEL_LIBRARIES[library])
        except ImportError as error:
            raise MissingDependencyError(
                f"demonstrator {source!r} needs {_MODEL_LIBRARIES[library]}, which is not installed here ({error}); "
                f"pip install {'sbx-rl' if library == 'sbx' else 'stable-baselines3'}") from error
        if not hasattr(module, algorithm):
            raise VintixError(f"demonstrator {source!r}: {_MODEL_LIBRARIES[library]} has no algorithm {algorithm!r}")
        model = call_plugin(f"task {task!r}: demonstrator {source!r}: {algorithm}.load", f"Is {path} a {algorithm} "
                            f"model saved by {_MODEL_LIBRARIES[library]}? Name the algorithm it was saved with",
                            getattr(module, algorithm).load, path, device="cpu")
        return ModelFileDemonstrator(model)
    from vintix.tasks.custom import load_callable

    demonstrator = call_plugin(f"task {task!r}: demonstrator {source!r}", "Fix it: the error is in its code",
                               load_callable(source, f"task {task!r}: demonstrator"), task)
    if not callable(getattr(demonstrator, "act", None)):
        raise VintixError(f"demonstrator {source!r} returned {type(demonstrator).__name__}, which has no "
                          "act(observations, envs) method (the Demonstrator protocol)")
    return cast(Demonstrator, demonstrator)


def refuse_untrusted(path: Path) -> None:
    """Raise unless `path` exists, is owned by this user and is writable by nobody else: a file that is
    unpickled on load runs the code of whoever could write it."""
    if not path.exists():
        raise VintixError(f"{path}: no such file")
    info = path.stat()
    foreign = hasattr(os, "getuid") and info.st_uid != os.getuid()
    if foreign or info.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        who = f"owned by user id {info.st_uid}" if foreign else "writable by other users"
        raise VintixError(f"{path} is {who}; it is unpickled on load, which runs any code in it, so vintix loads it "
                          f"only when only you can write it. If you trust it, copy it and `chmod go-w` the copy")
