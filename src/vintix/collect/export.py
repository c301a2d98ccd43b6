"""Learning histories as a Minari dataset: one Minari episode per episode of every history of a task.

Minari stores each episode with the observation that follows its last step (N + 1 observations for N
steps) and whether it terminated or was truncated. A history records both only when it was collected
with episode ends (docs/data-format.md §3.6; every `vintix collect` since they exist); older files and the
published dataset cannot be exported, and the error says so. Each Minari episode's metadata says where
it came from: the history file and its index, the episode's index in the history, and the noise level
ε at the episode's first and last step (from the schedule the history records), so the learning
histories' order and their rise from noise to expert play survive the export.

The dataset records the task's Gymnasium environment where it has one (the package's tasks, and your own
tasks registered with an ``env_id``), so ``dataset.recover_environment()`` makes it; otherwise (an
``env_factory`` task, whose env is your code) it records the env's own observation and action spaces, bounds
included, read off one env. Only a task this process does not know gets unbounded spaces.
"""

from __future__ import annotations

import os
import re
import shutil
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import minari
import numpy as np
from minari.data_collector import EpisodeBuffer
from minari.dataset.minari_dataset import parse_dataset_id
from minari.namespace import validate_namespace
from minari.storage.datasets_root_dir import get_dataset_path

from vintix.atomic import check_free_space
from vintix.collect.noise import NoiseSchedule
from vintix.data.discovery import TaskData, find_tasks
from vintix.data.layout import TERMINATED
from vintix.data.reader import LearningHistory
from vintix.errors import DatasetError, VintixError
from vintix.tasks import TaskSpec, action_space_of, find_task, gymnasium_id, make_env
from vintix.tasks.custom import import_code


def check_dataset_id(dataset_id: str) -> None:
    """VintixError unless `dataset_id` reads as Minari's ``[namespace/]name-vN``, each part a plain name: a part
    such as ``..`` would make Minari create folders outside its datasets root before it refused the id."""
    parts = dataset_id.split("/")
    plain = all(re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_-]*", part) for part in parts)
    try:  # Minari's own parse, so that no id it would refuse after making a folder gets that far
        namespace = parse_dataset_id(dataset_id)[0]
        if namespace is not None:
            validate_namespace(namespace)
    except (ValueError, TypeError):
        plain = False
    if not plain or not re.search(r"-v\d+$", parts[-1]):
        raise VintixError(f"Minari dataset id {dataset_id!r}: expected [namespace/]name-vN, each part letters, digits, "
                          "'_' or '-', e.g. vintix/reach-v3-v0")


def export_minari(root: str | os.PathLike[str], dataset_id: str, task: str | None = None,
                  description: str | None = None, author: str | None = None, author_email: str | None = None,
                  code_permalink: str | None = None, overwrite: bool = False) -> minari.MinariDataset:
    """Write the histories of one task of the dataset at `root` as the local Minari dataset `dataset_id`
    (under ``$MINARI_DATASETS_PATH``, default ``~/.minari/datasets``); `task` picks it where the dataset
    holds several; `author`, `author_email` and `code_permalink` go into Minari's metadata. A dataset of that
    id already there is an error, or with `overwrite` is replaced (only once the new one's histories have been
    read). Returns the dataset, loaded back by Minari."""
    check_dataset_id(dataset_id)
    data = _one_task(root, task)
    existing = dataset_id in minari.list_local_datasets()
    if existing and not overwrite:
        raise VintixError(f"a local Minari dataset {dataset_id!r} exists already; choose another id, or replace it "
                          "with --overwrite")
    if not data.history_paths:
        raise VintixError(f"{data.task_dir}: no histories to export")
    # Minari writes the rows again, uncompressed: about the histories' size on disk, and some.
    check_free_space(get_dataset_path(dataset_id), int(1.2 * sum(p.stat().st_size for p in data.history_paths)),
                     f"the Minari dataset {dataset_id!r} would", "free space, or point MINARI_DATASETS_PATH elsewhere")
    episodes, metadata = [], []
    for index, path in enumerate(data.history_paths):
        with LearningHistory(path) as history:
            for episode, meta in _episodes(history):
                episodes.append(episode)
                metadata.append({"history": path.name, "history_index": index, **meta})
    spec = find_task(data.task_name)
    env_spec = _env_spec(spec)
    observation_space, action_space = (None, None) if env_spec else _spaces(spec, data)
    if existing:
        minari.delete_dataset(dataset_id)
    with warnings.catch_warnings():
        # Meta-World's hidden goal is a Box with equal bounds by design (see `vintix.tasks.make`); Minari's advice
        # to name an author e-mail and a separate evaluation env is for datasets published to its server, and a
        # task made by your factory has no env spec by design (its spaces are recorded instead).
        warnings.filterwarnings("ignore", message=".*maximum and minimum values are equal.*")
        warnings.filterwarnings("ignore", message=".*is set to None.*", module="minari")
        warnings.filterwarnings("ignore", message="env_spec is None.*", module="minari")
        try:
            dataset = minari.create_dataset_from_buffers(
                dataset_id, episodes, env=env_spec, eval_env=env_spec, author=author, author_email=author_email,
                code_permalink=code_permalink, observation_space=observation_space, action_space=action_space,
                algorithm_name=f"vintix {'ε-greedy' if data.discrete else 'continuous'} noise distillation",
                description=description or f"Learning histories of {data.task_name} from {Path(root).name}: a "
                                           f"demonstrator's actions {NOISE[data.discrete]} annealed from 1 to 0.",
            )
            dataset.storage.update_episode_metadata(metadata)
        except BaseException:  # a half-written dataset (listed or not) would poison every later export of this id
            shutil.rmtree(get_dataset_path(dataset_id), ignore_errors=True)
            raise
    return dataset


NOISE = {False: "mixed with uniform noise", True: "replaced by uniformly random ones with a probability"}
"""How a history's noise enters its actions, by whether they are discrete (the description of an export)."""


def _env_spec(spec: TaskSpec | None) -> gym.envs.registration.EnvSpec | None:
    """The Gymnasium spec `recover_environment` makes the task's env from: the package's tasks', and your own
    tasks' made from a Gymnasium id (``module:EnvId`` imports the module first, as `gymnasium.make` does); None
    for a task made by your factory or unknown here (`spec` None)."""
    if spec is None or spec.domain == "bidexhands" or (spec.domain == "custom" and spec.env_id is None):
        return None
    env_id = gymnasium_id(spec) if spec.domain != "custom" else str(spec.env_id)
    module, _, name = env_id.rpartition(":")
    if module:  # through the trust gate: a dataset's task JSON may name this module
        import_code(module, f"task {spec.name!r}: env_id {env_id!r}", spec.named_by)
    return gym.spec(name)


def _spaces(spec: TaskSpec | None, data: TaskData) -> tuple[gym.spaces.Box, gym.spaces.Space]:
    """The task's observation and action spaces, read off one env where this process can make it, else
    unbounded Boxes of the dataset's dimensions (a discrete task's actions: Discrete(action_dim))."""
    if spec is None or spec.domain == "bidexhands":
        unbounded = np.float32(np.inf)
        actions = gym.spaces.Discrete(data.act_dim) if data.discrete else \
            gym.spaces.Box(-unbounded, unbounded, (data.act_dim,), np.float32)
        return gym.spaces.Box(-unbounded, unbounded, (data.obs_dim,), np.float32), actions
    env = make_env(spec.name)
    try:
        return env.observation_space, action_space_of(env.action_space)  # type: ignore[return-value]
    finally:
        env.close()


def _one_task(root: str | os.PathLike[str], task: str | None) -> TaskData:
    tasks = find_tasks(root)
    if task is not None:
        canonical = (spec.name if (spec := find_task(task)) is not None else task)
        tasks = [t for t in tasks if t.task_name in (task, canonical)]
    if len(tasks) != 1:
        names = ", ".join(t.task_name for t in find_tasks(root))
        raise VintixError(f"{root}: a Minari dataset holds one task; "
                          f"{'choose one with --task' if len(tasks) > 1 else f'no task {task!r} here'} ({names})")
    return tasks[0]


def _episodes(history: LearningHistory) -> list[tuple[EpisodeBuffer, dict[str, Any]]]:
    ends = history.episode_ends()
    if ends is None:
        raise DatasetError(history.path, "records no episode ends (final observations, terminated or truncated), "
                           "which a Minari episode needs; re-collect it with `vintix collect`")
    end_rows, kinds, final = ends
    rows = history.read(0, history.num_steps)
    epsilon = _epsilon(history)
    episodes = []
    start = 0
    for i, (end, kind) in enumerate(zip(end_rows.tolist(), kinds.tolist(), strict=True)):
        steps = end + 1 - start
        last = np.zeros(steps, dtype=bool)
        last[-1] = True
        buffer = EpisodeBuffer(
            id=None,
            observations=np.concatenate([rows["observation"][start:end + 1], final[i][None]]),
            actions=rows["action"][start:end + 1],
            rewards=rows["reward"][start:end + 1].astype(np.float64),
            terminations=last & (kind == TERMINATED),
            truncations=last & (kind != TERMINATED),
        )
        meta: dict[str, Any] = {"episode_in_history": i}
        if epsilon is not None:
            meta |= {"epsilon_first_step": float(epsilon[start]), "epsilon_last_step": float(epsilon[end])}
        episodes.append((buffer, meta))
        start = end + 1
    return episodes


def _epsilon(history: LearningHistory) -> np.ndarray | None:
    """The noise level of every row, from the schedule the history records (None if it records none)."""
    try:
        schedule = NoiseSchedule.from_recorded(history.attrs)
    except (KeyError, TypeError, ValueError):
        return None
    steps = int(history.attrs.get("steps", history.num_steps))
    return schedule.epsilon(np.arange(history.num_steps), steps)
