"""A dataset's task folders: each task's JSON (written, read, checked) and the history files beside it
(`find_tasks`); the layout: docs/data-format.md."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vintix.atomic import atomic_write_text, file_name, not_a_file
from vintix.data.layout import (
    ACTION_TYPES,
    PathLike,
    is_dim,
)
from vintix.errors import DatasetError, VintixError
from vintix.fields import checked_fields, read_json_object
from vintix.tasks.custom import register_specs


@dataclass
class TaskFile:
    """A task JSON's required fields, as `read_task_metadata` checks them (the official layout; the file may hold
    more: ``reward_scale``, ``group``, a task of your own's ``custom_task``)."""

    task_name: str
    """the registry's name of the task"""
    observation_shape: dict[str, Any]
    """``{"proprio": [obs_dim]}``"""
    action_dim: int
    """action channels, or a discrete task's number of actions"""
    action_type: str
    """'continuous' (or 'discrete', vintix's extension)"""


_REQUIRED_KEYS = tuple(field.name for field in dataclasses.fields(TaskFile))


def task_directory(root: PathLike, domain: str, task_dir_name: str) -> Path:
    """``<root>/<domain>/<task_dir_name>``: where a task's JSON and histories live. A task of your own is named by a
    file (a tasks file, a task JSON), so both names go through `vintix.atomic.file_name`: never a path out of root."""
    return Path(root) / file_name(domain) / file_name(task_dir_name)


def metadata_path(task_dir: PathLike) -> Path:
    """The task JSON is named after its folder: ``<task_dir>/<task_dir>.json``."""
    task_dir = Path(task_dir)
    return task_dir / f"{task_dir.name}.json"


def write_task_metadata(task_dir: PathLike, task_name: str, obs_dim: int, act_dim: int, discrete: bool = False,
                        **extra: Any) -> Path:
    """Write the task JSON atomically (extra keys such as ``reward_scale`` or ``group`` are kept); `discrete`: the
    task has `act_dim` discrete actions (``action_type`` 'discrete', our extension)."""
    clash = set(extra) & set(_REQUIRED_KEYS)
    if clash:
        raise ValueError(f"extra metadata keys {sorted(clash)} would overwrite required ones; pass them as arguments")
    meta = {"task_name": task_name, "observation_shape": {"proprio": [obs_dim]}, "action_dim": act_dim,
            "action_type": "discrete" if discrete else "continuous", **extra}
    path = metadata_path(task_dir)
    atomic_write_text(path, json.dumps(meta, indent=2) + "\n")
    return path


def read_task_metadata(task_dir: PathLike) -> dict[str, Any]:
    """Load and check the task JSON (`TaskFile`, through `vintix.fields.checked_fields`; the other keys are kept); see
    `metadata_dims` for the dims it declares."""
    path = metadata_path(task_dir)
    fix = "fix it or rewrite it with vintix.data.write_task_metadata()"
    if why := not_a_file(path):
        raise DatasetError(path, why.removeprefix(f"{path}: "))
    if not path.is_file():
        raise DatasetError(
            path, f"missing task metadata (keys {list(_REQUIRED_KEYS)}); write it with write_task_metadata()"
        )
    meta = read_json_object(path, DatasetError, fix)
    task = checked_fields(meta, TaskFile, path, DatasetError, fix)
    proprio = task.observation_shape.get("proprio")
    checks = {
        "task_name must be a non-empty string": task.task_name,
        "observation_shape must be {'proprio': [obs_dim]}": (
            isinstance(proprio, list) and len(proprio) == 1 and is_dim(proprio[0])
        ),
        "action_dim must be a positive integer": is_dim(task.action_dim),
        "action_type must be 'continuous' (or 'discrete', vintix's extension)": task.action_type in ACTION_TYPES,
    }
    for rule, ok in checks.items():
        if not ok:
            raise DatasetError(path, f"{rule}; {fix}")
    return meta


def register_dataset_task(task_dir: PathLike, meta: dict[str, Any]) -> None:
    """Register the task of your own whose spec its collector wrote into the task JSON `meta` (``custom_task``), so
    that the dataset's task can be made, trained on and evaluated in this process; nothing for a registered task.
    Reading a task JSON (`read_task_metadata`) registers nothing: this is done where a dataset is opened for use."""
    if "custom_task" not in meta:
        return
    path = metadata_path(task_dir)
    try:
        register_specs({meta["task_name"]: meta["custom_task"]}, str(path))
    except VintixError as error:
        raise DatasetError(path, f"its custom_task spec: {error}") from error


def metadata_dims(meta: dict[str, Any]) -> tuple[int, int]:
    """(obs_dim, act_dim) declared by a task JSON read with `read_task_metadata`."""
    return meta["observation_shape"]["proprio"][0], meta["action_dim"]


def task_dirs(root: PathLike) -> list[Path]:
    """Every ``<root>/<domain>/<task_dir>`` folder, sorted; hidden folders are skipped."""
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(root, "dataset root is not a directory; check the path")

    def subdirs(folder: Path) -> list[Path]:
        return sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))

    return [task for domain in subdirs(root) for task in subdirs(domain)]


NOT_A_HISTORY = "named like a history but not a regular file (a FIFO, a device, a folder or a broken link); remove it"
"""What is wrong with an entry of a task folder named ``*.h5`` that is not a file: a reader that skipped it would
pass a dataset with a hole in it as clean, and one that opened it could hang (a FIFO)."""


def history_entries(task_dir: PathLike) -> tuple[list[Path], list[Path]]:
    """The task's finished histories, sorted (``*.h5.partial`` files are unfinished and never match), and the entries
    named like one that are not regular files (`NOT_A_HISTORY`)."""
    named = sorted(Path(task_dir).glob("*.h5"))
    return [p for p in named if p.is_file()], [p for p in named if not p.is_file()]


def history_paths(task_dir: PathLike) -> list[Path]:
    """The task's finished histories, sorted; a DatasetError for an entry named like one that is not a file."""
    histories, strays = history_entries(task_dir)
    if strays:
        raise DatasetError(strays[0], NOT_A_HISTORY)
    return histories


@dataclass(frozen=True)
class TaskData:
    """One task folder of a dataset: its metadata and learning history files."""

    domain: str
    task_dir: Path
    task_name: str
    obs_dim: int
    act_dim: int
    """action channels, or a discrete task's number of actions"""
    metadata: dict[str, Any] = field(repr=False)
    history_paths: list[Path] = field(repr=False)

    @property
    def discrete(self) -> bool:
        """Whether the task's JSON declares discrete actions."""
        return bool(self.metadata["action_type"] == "discrete")


def find_tasks(root: PathLike) -> list[TaskData]:
    """Discover every task of a dataset root, registering the tasks of your own it carries
    (`register_dataset_task`); raises DatasetError on a missing or malformed task JSON."""
    tasks = []
    for task_dir in task_dirs(root):
        meta = read_task_metadata(task_dir)
        register_dataset_task(task_dir, meta)
        obs_dim, act_dim = metadata_dims(meta)
        tasks.append(TaskData(
            task_dir.parent.name, task_dir, meta["task_name"], obs_dim, act_dim, meta, history_paths(task_dir)
        ))
    return tasks
