"""The registry of every task of the Vintix paper (102 tasks in 4 domains), plus the package's own hidden-goal tasks.

The table ships inside the package (`paper_tasks.csv`, built by `scripts/build_task_table.py` from
the paper's appendix tables) so nothing outside the package is read at run time.

Naming: MuJoCo tasks use gymnasium's `-v5` ids. The paper's tables and the published dataset say
`-v4`, but the dimensions they hold are the v5 ones (Ant 105, Humanoid 348, ...), so `-v4` names are
accepted as aliases of the `-v5` task (Pusher too, although gymnasium's own Pusher-v4 does not load
on mujoco 3: the alias makes the v5 env). Meta-World tasks use metaworld 3.x's `-v3` ids; the
paper's bare names and `-v2` names are aliases. Industrial Benchmark is `industrial-benchmark-<p>-v1`
(alias `IB-p-<p>`); Bi-DexHands uses the dataset's `Hand-*` names (alias: the score table's `shadowhand*`).
The toy domain's `point-goal-v1` (`vintix.tasks.toy`) and the hidden-goal MuJoCo tasks
(`Reacher-hidden-v5`, `vintix.tasks.reacher_hidden`) are not paper tasks and have no published scores.
"""

from __future__ import annotations

import csv
import difflib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from functools import cache
from importlib import resources
from typing import Literal

from vintix.errors import UnknownTaskError

Domain = Literal["mujoco", "metaworld", "industrial_benchmark", "bidexhands", "toy", "icrl", "custom"]
Split = Literal["train", "test"]
DOMAINS: tuple[Domain, ...] = ("mujoco", "metaworld", "industrial_benchmark", "bidexhands", "toy", "icrl", "custom")
"""'icrl': the discrete benchmarks in-context RL is measured on (Dark Room, Key-to-Door, bandits;
`vintix.tasks.discrete_benchmarks`);
'custom': tasks registered from outside the package (`register_task`)"""
ActionType = Literal["continuous", "discrete"]
ACTION_TYPES: tuple[ActionType, ...] = ("continuous", "discrete")
"""A task acts in a bounded Box (``act_dim`` channels) or a Discrete space (``act_dim`` actions, 0 to act_dim - 1)."""

PAPER_PROVENANCE = (
    "paper: Vintix (ICML 2025) appendix 'Task-Level Performance'; MuJoCo -v4 names with v5 dims, "
    "Meta-World v2 with 100-step episodes, Industrial Benchmark classic reward / 100 over 250 steps"
)

@dataclass(frozen=True)
class ReferenceScore:
    """An episode-return statistic with where it came from."""

    mean: float
    std: float | None
    provenance: str


@dataclass(frozen=True)
class TaskSpec:
    """Everything the pipeline needs to know about one task."""

    name: str
    domain: Domain
    group: str
    """Tasks of a group share observation/action encoders and the action head."""
    obs_dim: int
    act_dim: int
    """Box tasks: action channels; Discrete tasks: the number of actions"""
    episode_length: int
    """Maximum steps per episode (Bi-DexHands: the paper's mean length, tasks end themselves)."""
    reward_scale: float
    """Multiplies rewards before they enter the model."""
    split: Split
    aliases: tuple[str, ...]
    paper_random: ReferenceScore | None
    """None for a task that is not the paper's (no published scores)"""
    paper_expert: ReferenceScore | None
    paper_vintix_normalized: ReferenceScore | None
    paper_history_length: int
    """Steps per learning history in the paper's dataset."""
    paper_histories: int
    """Learning histories per task in the paper's dataset."""
    env_id: str | None = None
    """custom tasks: the Gymnasium id their env is made with (``module:EnvId`` imports the module first)"""
    env_factory: str | None = None
    """custom tasks: ``module:callable`` returning their env (instead of `env_id`)"""
    reference_random: float | None = None
    """custom tasks: the random policy's mean episode return, for normalized scores (None: no scores)"""
    reference_expert: float | None = None
    """custom tasks: the demonstrator's mean episode return, for normalized scores"""
    source: str | None = dataclass_field(default=None, compare=False)
    """custom tasks: the file that registered them (a tasks file, a checkpoint's config...), named in errors;
    None for `register_task` from Python"""
    action_type: ActionType = "continuous"
    """'continuous' (a bounded Box) or 'discrete' (a Discrete space of act_dim actions starting at 0)"""
    named_by: str | None = dataclass_field(default=None, compare=False)
    """custom tasks registered from a file a run wrote (a checkpoint's config, a dataset's task JSON), not by
    you: that file. The code its spec names runs only when trusted (`vintix.tasks.custom.code_trusted`)."""

    @property
    def discrete(self) -> bool:
        """Whether the task acts in a Discrete space."""
        return self.action_type == "discrete"

    @property
    def episode_limit(self) -> int | None:
        """The most steps an episode can have; None where episodes end themselves and `episode_length`
        is only their mean (Bi-DexHands)."""
        return None if self.domain == "bidexhands" else self.episode_length


def _optional_float(text: str) -> float | None:
    return float(text) if text else None


def _spec_from_row(row: dict[str, str]) -> TaskSpec:
    def score(prefix: str) -> ReferenceScore:
        return ReferenceScore(float(row[f"{prefix}_mean"]), _optional_float(row[f"{prefix}_std"]), PAPER_PROVENANCE)

    return TaskSpec(
        name=row["name"],
        domain=row["domain"],  # type: ignore[arg-type]
        group=row["group"],
        obs_dim=int(row["obs_dim"]),
        act_dim=int(row["act_dim"]),
        episode_length=int(row["episode_length"]),
        reward_scale=float(row["reward_scale"]),
        split=row["split"],  # type: ignore[arg-type]
        aliases=tuple(row["aliases"].split()),
        paper_random=score("random"),
        paper_expert=score("expert"),
        paper_vintix_normalized=score("paper_vintix"),
        paper_history_length=int(row["paper_history_length"]),
        paper_histories=int(row["paper_histories"]),
    )


def _toy_tasks() -> list[TaskSpec]:
    from vintix.tasks import toy

    return [TaskSpec(name="point-goal-v1", domain="toy", group="point-goal", obs_dim=1, act_dim=1,
                     episode_length=toy.EPISODE_LENGTH, reward_scale=1.0, split="train", aliases=("point-goal",),
                     paper_random=None, paper_expert=None, paper_vintix_normalized=None, paper_history_length=0,
                     paper_histories=0)]


HIDDEN_GOAL_MUJOCO_TASKS = ("Reacher-hidden-v5", "HalfCheetah-Vel-v5", "HalfCheetah-Dir-v5", "Ant-Dir-v5")
"""MuJoCo tasks of the package's own whose goal only the rewards reveal (not the paper's; no published scores):
Reacher-hidden (`vintix.tasks.reacher_hidden`) and the meta-RL benchmarks (`vintix.tasks.meta_mujoco`)."""
META_RL_TASKS = HIDDEN_GOAL_MUJOCO_TASKS[1:]
"""The meta-RL locomotion benchmarks (`vintix.tasks.meta_mujoco`)."""


def has_hidden_goal(spec: TaskSpec) -> bool:
    """Whether `spec`'s env keeps a goal it never shows, drawn from its seed (Meta-World, the toy, the discrete
    benchmarks, Reacher-hidden-v5, the meta-RL tasks): the tasks an evaluation's goal protocol is about."""
    return spec.domain in ("metaworld", "toy", "icrl") or spec.name in HIDDEN_GOAL_MUJOCO_TASKS


def _hidden_goal_mujoco_tasks() -> list[TaskSpec]:
    # Reacher-v5's episode length and reward scale; its own encoder group, since it observes 6 of Reacher's 10
    # entries (`vintix.tasks.reacher_hidden`).
    reacher = TaskSpec(name="Reacher-hidden-v5", domain="mujoco", group="mujoco-reacher-hidden", obs_dim=6, act_dim=2,
                       episode_length=50, reward_scale=0.1, split="train", aliases=(), paper_random=None,
                       paper_expert=None, paper_vintix_normalized=None, paper_history_length=0, paper_histories=0)
    # The meta-RL tasks observe their bodies as gymnasium's v5 envs do: the same encoder groups, 200-step episodes.
    bodies = {"HalfCheetah-Vel-v5": ("mujoco-halfcheetah", 17, 6), "HalfCheetah-Dir-v5": ("mujoco-halfcheetah", 17, 6),
              "Ant-Dir-v5": ("mujoco-ant", 105, 8)}
    return [reacher] + [
        TaskSpec(name=name, domain="mujoco", group=group, obs_dim=obs_dim, act_dim=act_dim, episode_length=200,
                 reward_scale=0.1, split="train", aliases=(), paper_random=None, paper_expert=None,
                 paper_vintix_normalized=None, paper_history_length=0, paper_histories=0)
        for name, (group, obs_dim, act_dim) in bodies.items()]


@cache
def _builtin_tasks() -> dict[str, TaskSpec]:
    table = resources.files("vintix.tasks").joinpath("paper_tasks.csv").read_text()
    paper = list(map(_spec_from_row, csv.DictReader(table.splitlines())))
    from vintix.tasks.discrete_benchmarks import icrl_task_specs

    return {spec.name: spec for spec in paper + _toy_tasks() + _hidden_goal_mujoco_tasks() + icrl_task_specs()}


def builtin_tasks(domain: str) -> list[TaskSpec]:
    """The package's own tasks of `domain`, without loading task plug-ins."""
    return [spec for spec in _builtin_tasks().values() if spec.domain == domain]


_custom: dict[str, TaskSpec] = {}
"""Tasks registered from outside the package, by name (`register_task`)"""


_plugins_loaded = False


def load_task_plugins() -> None:
    """Register the tasks of ``VINTIX_TASKS`` files and ``vintix.tasks`` entry points, once per process
    (`vintix.tasks.custom`)."""
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True  # before loading: the plug-ins' own registrations look tasks up
    from vintix.tasks.custom import load_plugins

    try:
        load_plugins()
    except Exception:
        _plugins_loaded = False  # the error is the user's to fix; the next lookup tries again
        raise


def _tasks() -> dict[str, TaskSpec]:
    load_task_plugins()
    return _builtin_tasks() | _custom if _custom else _builtin_tasks()


@cache
def _builtin_names() -> dict[str, str]:
    return _lookup(_builtin_tasks().values())


def _lookup(specs: Iterable[TaskSpec]) -> dict[str, str]:
    lookup = {}
    for spec in specs:
        lookup[spec.name] = spec.name
        lookup.update({alias: spec.name for alias in spec.aliases})
    return lookup


def _names_and_aliases() -> dict[str, str]:
    load_task_plugins()
    return _builtin_names() | _lookup(_custom.values()) if _custom else _builtin_names()


def get_task(name: str) -> TaskSpec:
    """The task called `name` (or one of its aliases); raises UnknownTaskError with close matches."""
    lookup = _names_and_aliases()
    if name in lookup:
        return _tasks()[lookup[name]]
    close = difflib.get_close_matches(name, list(lookup), n=5, cutoff=0.6)
    hint = f" Did you mean: {', '.join(close)}?" if close else ""
    raise UnknownTaskError(f"unknown task {name!r}.{hint} Run `vintix tasks` to list all {len(_tasks())} tasks.")


def find_task(name: str) -> TaskSpec | None:
    """The task called `name` (or one of its aliases), or None for a name the registry does not know
    (a dataset's or checkpoint's task from elsewhere)."""
    index = _names_and_aliases().get(name)
    return None if index is None else _tasks()[index]


def list_tasks(domain: str | None = None, split: str | None = None, group: str | None = None) -> list[TaskSpec]:
    """Tasks in registry order, optionally filtered; an unknown filter value is an error, not an empty list."""
    every_task = list(_tasks().values())
    tasks = every_task
    for field, value in (("domain", domain), ("split", split), ("group", group)):
        if value is None:
            continue
        known = sorted({getattr(t, field) for t in every_task})
        if value not in known:
            raise UnknownTaskError(f"unknown {field} {value!r}; known: {', '.join(known)}")
        tasks = [t for t in tasks if getattr(t, field) == value]
    return tasks


def resolve_tasks(selectors: list[str]) -> list[TaskSpec]:
    """Expand task names, domain names and split names ('train'/'test') into tasks, without repeats.

    `["mujoco", "door-open-v3", "test"]` is every MuJoCo task, door-open, and every test task.
    """
    selected: dict[str, TaskSpec] = {}
    for selector in selectors:
        if selector in DOMAINS:
            found = list_tasks(domain=selector)
        elif selector in ("train", "test"):
            found = list_tasks(split=selector)
        else:
            found = [get_task(selector)]
        selected.update((t.name, t) for t in found)
    return list(selected.values())


def select_tasks(selectors: Sequence[str], groups: Sequence[str], checkpoint_tasks: Sequence[str] = ()
                 ) -> tuple[list[TaskSpec], list[str]]:
    """Tasks to evaluate and notes on the ones skipped: a domain or split keeps the tasks of the
    checkpoint's groups and those it has statistics for (an imported model's groups have other names);
    a task named explicitly that is neither is an error."""
    selectors = [s for selector in selectors for s in selector.split(",") if s]
    named = {get_task(s).name for s in selectors if s not in DOMAINS and s not in ("train", "test")}
    known = {spec.name for task in checkpoint_tasks if (spec := find_task(task)) is not None}
    kept, skipped = [], []
    for spec in resolve_tasks(selectors):
        if spec.group in groups or spec.name in known:
            kept.append(spec)
        elif spec.name in named:
            raise UnknownTaskError(
                f"task {spec.name!r} is in group {spec.group!r}, which the model has no encoder for "
                f"(it has {', '.join(sorted(groups))})"
            )
        else:
            skipped.append(spec.name)
    notes = ([f"skipped {len(skipped)} selected task(s) whose group the checkpoint lacks: {', '.join(skipped)}"]
             if skipped else [])
    if not kept:
        raise UnknownTaskError(
            f"none of {selectors} is a task of the model's groups ({', '.join(sorted(groups))})")
    return kept, notes
