"""Your own tasks: any Gymnasium env with a bounded Box or a Discrete action space, registered from outside the package.

Three ways, all of which every vintix process (every CLI command, every Ray worker) sees:

- Python: ``vintix.register_task("Pendulum-v1", env_id="Pendulum-v1", obs_dim=3, act_dim=1,
  episode_length=200)``, in your own code before you call vintix;
- a tasks file, YAML, named by the environment variable ``VINTIX_TASKS`` (several: separated by ``:``) or by
  ``vintix --tasks-file FILE <command>``::

      tasks:
        Pendulum-v1:
          env_id: Pendulum-v1        # or env_factory: my_package.envs:make_pendulum
          obs_dim: 3
          act_dim: 1
          episode_length: 200
          group: pendulum            # tasks of one group share encoders and a head (default: the name)
          reward_scale: 0.1          # rewards are multiplied by it before the model sees them
          reference_random: -1200    # mean returns that normalize scores (optional)
          reference_expert: -150
          action_type: continuous    # or discrete: a Discrete(act_dim) space, actions 0 to act_dim - 1

- a plug-in package: an entry point in the group ``vintix.tasks`` naming a function that registers its
  tasks (``[project.entry-points."vintix.tasks"] mine = "my_package.vintix_tasks:register"``).

A checkpoint keeps the specs of the custom tasks it was trained on (a dataset's task JSON too), and loading
it registers them. A spec that contradicts its env (dims, an unbounded or non-Box action space) is an error
when the env is made.

**Trust.** Code named by a file that a run wrote, which may come from anyone (a downloaded checkpoint or
dataset), runs only when you say so, as with Hugging Face's ``trust_remote_code``: a spec registered from such a
file whose env is made by code (``env_factory``, or an ``env_id`` that reads ``module:EnvId``) is refused when
its env is made, unless you registered the same task yourself (tasks file, ``VINTIX_TASKS``, Python, a
plug-in) or trust the file's code: ``vintix --trust-code <command>``, ``VINTIX_TRUST_CODE=1`` (every process,
Ray workers included), or ``trust_code=True`` where Python loads a checkpoint. A plain Gymnasium id (an env
of a package you installed) needs no trust. Files you name yourself (tasks files, recipes and the
demonstrators they name) are yours and run by design.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path
from types import ModuleType
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

from vintix.atomic import read_regular_text
from vintix.errors import PluginError, VintixError, call_plugin
from vintix.tasks import registry
from vintix.tasks.make import action_space_problem
from vintix.tasks.registry import ACTION_TYPES, TaskSpec

ENV_VARIABLE = "VINTIX_TASKS"
TRUST_VARIABLE = "VINTIX_TRUST_CODE"
ENTRY_POINT_GROUP = "vintix.tasks"
SPEC_FIELDS = ("env_id", "env_factory", "obs_dim", "act_dim", "episode_length", "group", "reward_scale",
               "reference_random", "reference_expert", "split", "aliases", "action_type")
"""What a tasks file (or `register_task`) may say about a task"""


class TaskSpecError(VintixError, ValueError):
    """A custom task whose spec is incomplete, contradicts itself or its env, or clashes with another task."""


def register_task(
    name: str, *, obs_dim: int, act_dim: int, episode_length: int, env_id: str | None = None,
    env_factory: str | None = None, group: str | None = None, reward_scale: float = 1.0,
    reference_random: float | None = None, reference_expert: float | None = None, split: str = "train",
    aliases: tuple[str, ...] | list[str] = (), action_type: str = "continuous",
) -> TaskSpec:
    """Add a task of your own to the registry (see this module's docstring); returns its spec; `action_type`
    'discrete': the env acts in Discrete(act_dim) (actions 0 to act_dim - 1). Registering
    the same spec again is a no-op (and vouches for its code: `code_trusted`); another spec under a taken name
    or alias is a TaskSpecError, as is a group whose other tasks have other dims."""
    spec = build_spec(name, obs_dim=obs_dim, act_dim=act_dim, episode_length=episode_length, env_id=env_id,
                      env_factory=env_factory, group=group, reward_scale=reward_scale,
                      reference_random=reference_random, reference_expert=reference_expert, split=split,
                      aliases=aliases, action_type=action_type)
    return add_spec(spec)


def add_spec(spec: TaskSpec) -> TaskSpec:
    """Put `spec` in the registry once it fits there (`check_fits_registry`), replacing an equal one; returns it."""
    check_fits_registry(spec)
    registry._custom[spec.name] = spec
    return spec


def build_spec(
    name: str, *, obs_dim: int, act_dim: int, episode_length: int, env_id: str | None = None,
    env_factory: str | None = None, group: str | None = None, reward_scale: float = 1.0,
    reference_random: float | None = None, reference_expert: float | None = None, split: str = "train",
    aliases: tuple[str, ...] | list[str] = (), source: str | None = None, action_type: str = "continuous",
) -> TaskSpec:
    """A custom task's spec, checked against itself (not yet against the registry); `source`: the file it came
    from, named in errors."""
    if (env_id is None) == (env_factory is None):
        raise TaskSpecError(f"task {name!r}: give one of env_id (a Gymnasium id) and env_factory (module:callable)")
    if env_factory is not None and ":" not in env_factory:
        raise TaskSpecError(f"task {name!r}: env_factory must read module:callable, got {env_factory!r}")
    sizes = {"obs_dim": obs_dim, "act_dim": act_dim, "episode_length": episode_length}
    bad = [f"{k}={v!r}" for k, v in sizes.items() if not isinstance(v, int) or isinstance(v, bool) or v < 1]
    if bad or split not in ("train", "test") or not reward_scale > 0:
        got = ", ".join(bad) or f"split={split!r}, reward_scale={reward_scale}"
        raise TaskSpecError(f"task {name!r}: obs_dim, act_dim and episode_length must be integers >= 1, split train "
                            f"or test, reward_scale > 0; got {got}")
    if action_type not in ACTION_TYPES:
        raise TaskSpecError(f"task {name!r}: action_type must be one of {', '.join(ACTION_TYPES)}, got {action_type!r}")
    if (reference_random is None) != (reference_expert is None) or (
            reference_random is not None and reference_expert is not None and not reference_expert > reference_random):
        raise TaskSpecError(f"task {name!r}: give both reference_random and reference_expert (expert above random) "
                            f"or neither; got {reference_random} and {reference_expert}")
    return TaskSpec(
        name=name, domain="custom", group=group or name, obs_dim=obs_dim, act_dim=act_dim,
        episode_length=episode_length, reward_scale=float(reward_scale), split=split,  # type: ignore[arg-type]
        aliases=tuple(aliases), paper_random=None, paper_expert=None, paper_vintix_normalized=None,
        paper_history_length=0, paper_histories=0, env_id=env_id, env_factory=env_factory,
        reference_random=None if reference_random is None else float(reference_random),
        reference_expert=None if reference_expert is None else float(reference_expert), source=source,
        action_type=action_type,
    )


def _from(spec: TaskSpec) -> str:
    return f" (from {spec.source})" if spec.source else ""


def check_fits_registry(spec: TaskSpec) -> None:
    """TaskSpecError where `spec` takes a name or alias another spec has, or joins a group whose tasks have
    other dims (they share encoders and a head); both errors say where the other spec came from."""
    taken = registry._names_and_aliases()
    for label in (spec.name, *spec.aliases):
        owner = taken.get(label)
        if owner is not None and registry._tasks()[owner] != spec:
            other = registry._tasks()[owner]
            whose = " (a task of the package)" if other.domain != "custom" else _from(other)
            raise TaskSpecError(f"task {spec.name!r}{_from(spec)}: the name {label!r} is already task {owner!r}"
                                f"{whose}; choose another name")
    member = next((t for t in registry._tasks().values() if t.group == spec.group and t.name != spec.name), None)
    if member is not None and (member.obs_dim, member.act_dim, member.action_type) != (
            spec.obs_dim, spec.act_dim, spec.action_type):
        raise TaskSpecError(
            f"task {spec.name!r}{_from(spec)}: group {spec.group!r} has obs_dim {member.obs_dim}, act_dim "
            f"{member.act_dim} and {member.action_type} actions (task {member.name!r}{_from(member)}), this task "
            f"{spec.obs_dim}, {spec.act_dim} and {spec.action_type}: tasks of a group share encoders and a head; give "
            "it its own group")


def spec_to_json(spec: TaskSpec) -> dict[str, Any]:
    """A custom task's spec as a tasks-file entry (what a checkpoint keeps)."""
    data = {field: getattr(spec, field) for field in SPEC_FIELDS}
    data["aliases"] = list(spec.aliases)
    return data


def spec_from_mapping(name: str, fields: Mapping[str, Any], where: str) -> TaskSpec:
    """`build_spec` from a tasks file's (or a checkpoint's) entry; unknown fields are an error."""
    if not isinstance(fields, Mapping):
        raise TaskSpecError(f"{where}: task {name!r} must be a mapping of {', '.join(SPEC_FIELDS)}")
    unknown = sorted(set(fields) - set(SPEC_FIELDS))
    if unknown:
        raise TaskSpecError(f"{where}: task {name!r} has unknown field(s) {unknown}; known: {', '.join(SPEC_FIELDS)}")
    try:
        return build_spec(str(name), **dict(fields), source=where)
    except TypeError as error:  # a missing required field
        raise TaskSpecError(f"{where}: task {name!r}: {error}") from error


def register_from_mapping(name: str, fields: Mapping[str, Any], where: str) -> TaskSpec:
    """`register_task` from a tasks file's entry (the user's own: its code is trusted)."""
    return add_spec(spec_from_mapping(name, fields, where))


def register_tasks_file(path: str | os.PathLike[str]) -> list[TaskSpec]:
    """Register every task of a YAML tasks file (this module's docstring shows one)."""
    path = Path(path)
    try:
        data = yaml.safe_load(read_regular_text(path))
    except OSError as error:
        raise TaskSpecError(f"tasks file {path}: {error.strerror or error}; check the path ({ENV_VARIABLE} or "
                            "--tasks-file)") from error
    except yaml.YAMLError as error:
        raise TaskSpecError(f"tasks file {path}: not valid YAML ({error})") from error
    if not isinstance(data, dict) or not isinstance(data.get("tasks"), dict) or not data["tasks"]:
        raise TaskSpecError(f"tasks file {path}: needs a non-empty 'tasks:' mapping of task name -> fields")
    return [register_from_mapping(name, fields, f"tasks file {path}") for name, fields in data["tasks"].items()]


def load_plugins() -> None:
    """Register the tasks of ``VINTIX_TASKS`` files and of ``vintix.tasks`` entry points."""
    from importlib.metadata import entry_points

    for entry in entry_points(group=ENTRY_POINT_GROUP):
        try:
            register = entry.load()
            register()
        except (Exception, SystemExit) as error:  # a broken plug-in is named (sys.exit too: it would exit 0 silently)
            raise TaskSpecError(f"the {ENTRY_POINT_GROUP} entry point {entry.name!r} ({entry.value}) failed: "
                                f"{error!r}; fix or uninstall the package that declares it") from error
    for file in filter(None, os.environ.get(ENV_VARIABLE, "").split(os.pathsep)):
        register_tasks_file(file)


def import_code(module: str, what: str, named_by: str | None = None) -> ModuleType:
    """The one gate of every import of code that vintix is told to run by name: env factories, ``module:EnvId``
    ids, demonstrators, whatever path a file's name reaches (tests/test_bad_inputs.py fails on an
    ``import_module`` anywhere else). `named_by`: the checkpoint's or dataset's file that named it, if not the
    user: then the import is refused (UntrustedCodeError) unless code is trusted (`code_trusted`)."""
    if not all(part.isidentifier() for part in module.split(".")):  # "", ".rel", "a..b", "a b"
        raise TaskSpecError(f"{what}: {module!r} is not a module name; write an absolute one, package.module:name "
                            "(a relative .module has no package to be relative to here)")
    if named_by is not None and not code_trusted():
        raise untrusted(what, named_by, f"module {module!r}")
    try:
        return importlib.import_module(module)
    except ImportError:
        raise  # the caller says where the module was looked for
    except (Exception, SystemExit) as error:  # noqa: BLE001 - code that fails as it is imported is named
        raise PluginError(f"{what}: importing module {module!r} raised {type(error).__name__}: {error}. Fix the "
                          "module: the error is in its code") from error


def load_callable(reference: str, what: str, named_by: str | None = None) -> Callable[..., Any]:
    """The object ``module:attribute`` names (imported through `import_code`), which must be callable; `what` names
    it in errors, `named_by` the file that named it (None: the user)."""
    module, _, attribute = reference.partition(":")
    try:
        target: Any = import_code(module, what, named_by)
        for part in attribute.split("."):
            target = getattr(target, part)
    except (ImportError, AttributeError) as error:
        raise TaskSpecError(f"{what} {reference!r} cannot be loaded ({error}); is its module importable here "
                            "(installed, or on PYTHONPATH)?") from error
    if not callable(target):
        raise TaskSpecError(f"{what} {reference!r} is not callable")
    return target


class UntrustedCodeError(TaskSpecError):
    """A task whose spec came from a file a run wrote names code to run, and nobody said to trust it."""


def code_trusted() -> bool:
    """Whether code that a checkpoint's or dataset's file names may run in this process (``VINTIX_TRUST_CODE``;
    `vintix --trust-code` sets it)."""
    return os.environ.get(TRUST_VARIABLE, "").strip().lower() in ("1", "true", "yes")


def code_it_runs(spec: TaskSpec) -> str | None:
    """What code making `spec`'s env imports and calls, if any: its env_factory, or a ``module:EnvId`` id's
    module (a plain Gymnasium id is an env of an installed package)."""
    if spec.env_factory is not None:
        return f"env_factory {spec.env_factory!r}"
    if spec.env_id is not None and ":" in spec.env_id:
        return f"env_id {spec.env_id!r} (it imports module {spec.env_id.partition(':')[0]!r})"
    return None


def refuse_untrusted_code(spec: TaskSpec) -> None:
    """UntrustedCodeError where `spec` came from a run's file and names code that nobody trusted."""
    code = code_it_runs(spec)
    if spec.named_by is None or code is None or code_trusted():
        return
    raise untrusted(f"task {spec.name!r}", spec.named_by, code)


def untrusted(what: str, named_by: str, code: str) -> UntrustedCodeError:
    """The refusal of `code` that the file `named_by` names for `what`, and the two ways to allow it."""
    return UntrustedCodeError(
        f"{what} comes from {named_by}, which names code to run: {code}. vintix runs code that a checkpoint or "
        "dataset names only when you say so: register the task yourself (a tasks file: vintix --tasks-file FILE, "
        f"or {ENV_VARIABLE}), or, if you trust where the file came from, vintix --trust-code <command> "
        f"({TRUST_VARIABLE}=1; in Python, trust_code=True)")


class NumberRewards(gym.Wrapper):
    """A custom env whose step returns a reward that is not one number (``np.array([r])``, a list) raises one
    TaskSpecError naming the task and the fix, where the collector and the agent would otherwise fail far from it."""

    def __init__(self, env: gym.Env, task: str) -> None:
        super().__init__(env)
        self.task = task

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        observation, given, terminated, truncated, info = self.env.step(action)
        reward: Any = given  # typed as a float by gymnasium; an env of one's own may return anything
        number = np.ndim(reward) == 0 and np.issubdtype(np.asarray(reward).dtype, np.number)
        if not number or isinstance(reward, (bool, np.bool_)):
            raise TaskSpecError(f"task {self.task!r}: its env's step returned the reward {reward!r} "
                                f"({type(reward).__name__}{f' of shape {np.shape(reward)}' if np.ndim(reward) else ''}"
                                "); a reward is one number: return float(reward) from step()")
        return observation, float(reward), terminated, truncated, info


def make_custom_env(spec: TaskSpec, **kwargs: Any) -> gym.Env:
    """`spec`'s env, capped at its episode length, checked against its dims and action bounds."""
    refuse_untrusted_code(spec)
    env: gym.Env
    if spec.env_factory is not None:
        factory = load_callable(spec.env_factory, f"task {spec.name!r}: env_factory", spec.named_by)
        made = call_plugin(f"task {spec.name!r}{_from(spec)}: its env_factory {spec.env_factory!r}",
                           "Fix the factory: the error is in its code", factory, **kwargs)
        env = gym.wrappers.TimeLimit(made, spec.episode_length)
    else:
        assert spec.env_id is not None  # register_task requires one of the two
        import_env_module(spec)
        try:
            env = call_plugin(f"task {spec.name!r}{_from(spec)}: gymnasium's make({spec.env_id!r})",
                              "Fix the env (or its registration)", gym.make, spec.env_id,
                              max_episode_steps=spec.episode_length, **kwargs)
        except PluginError as error:
            if isinstance(error.__cause__, gym.error.Error):
                raise TaskSpecError(f"task {spec.name!r}: gymnasium cannot make env {spec.env_id!r} "
                                    f"({error.__cause__})") from error.__cause__
            raise
    check_env_fits(spec, env)
    return NumberRewards(env, spec.name)


def import_env_module(spec: TaskSpec) -> None:
    """Import the module of a ``module:EnvId`` env id through the gate (`import_code`), so that gymnasium, which
    would import it itself, finds it imported."""
    if spec.env_id is not None and ":" in spec.env_id:
        import_code(spec.env_id.rpartition(":")[0], f"task {spec.name!r}: env_id {spec.env_id!r}", spec.named_by)


def check_env_fits(spec: TaskSpec, env: gym.Env) -> None:
    """A TaskSpecError (the env closed) where `env`'s spaces contradict `spec`."""
    problems = []
    obs_shape = getattr(env.observation_space, "shape", None)
    if obs_shape != (spec.obs_dim,):
        problems.append(f"observations of shape {obs_shape}, the spec says obs_dim {spec.obs_dim}")
    space = env.action_space
    unusable = action_space_problem(space)
    if unusable is not None:
        problems.append(unusable)
    elif spec.discrete and (not isinstance(space, gym.spaces.Discrete) or int(space.n) != spec.act_dim):
        problems.append(f"action space {space}, the spec says Discrete({spec.act_dim}) (action_type discrete)")
    elif not spec.discrete and (not isinstance(space, gym.spaces.Box) or space.shape != (spec.act_dim,)):
        hint = " (a Discrete env: action_type discrete, act_dim its number of actions)" if isinstance(
            space, gym.spaces.Discrete) else ""
        problems.append(f"action space {space}, the spec says a Box of act_dim {spec.act_dim}{hint}")
    elif isinstance(space, gym.spaces.Box) and not space.is_bounded("both"):
        problems.append(f"action space {space} is unbounded; vintix's noise draws uniform actions within bounds")
    if problems:
        env.close()
        raise TaskSpecError(f"task {spec.name!r}: its env has {'; '.join(problems)}; fix the spec or the env")


def custom_specs(tasks: list[str]) -> dict[str, dict[str, Any]]:
    """The tasks-file entries of those of `tasks` that are custom (what a checkpoint keeps)."""
    specs = {}
    for name in tasks:
        spec = registry.find_task(name)
        if spec is not None and spec.domain == "custom":
            specs[spec.name] = spec_to_json(spec)
    return specs


def register_specs(specs: Mapping[str, Any], where: str, trust_code: bool = False) -> None:
    """Register the custom task specs that the file `where` (a checkpoint's config, a dataset's task JSON, a
    results folder's run.json) keeps and this process does not know yet. Those are marked as named by
    `where`, and the code they name runs only when trusted (this module's docstring), or with `trust_code`."""
    if not isinstance(trust_code, bool):  # "false" is a true value: a string must not decide to run code
        raise VintixError(f"trust_code must be True or False, got {trust_code!r} ({type(trust_code).__name__})")
    for name, fields in specs.items():
        spec = spec_from_mapping(name, fields, where)
        check_fits_registry(spec)
        if registry.find_task(spec.name) is None:  # a known one stays as registered (and as trusted) before
            registry._custom[spec.name] = replace(spec, named_by=None if trust_code else where)


__all__ = ["TaskSpecError", "UntrustedCodeError", "check_env_fits", "code_trusted", "custom_specs", "import_code",
           "import_env_module", "load_callable", "make_custom_env", "register_specs",
           "register_task", "register_tasks_file"]
