"""Dataset validation and statistics (behind ``vintix data validate`` and ``vintix data stats``).

Validation reports every problem it finds instead of stopping at the first, one message per kind
of problem per file, each naming the fix. It reads histories one group (≤ 10,000 rows) at a time,
so memory stays small however large the dataset is. The format it checks is specified in
docs/data-format.md.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from vintix.data.discovery import (
    NOT_A_HISTORY,
    find_tasks,
    history_entries,
    metadata_dims,
    metadata_path,
    read_task_metadata,
    register_dataset_task,
    task_dirs,
)
from vintix.data.layout import (
    DTYPES,
    EPISODE_END_DATASETS,
    EPISODE_END_KIND,
    EPISODE_END_ROW,
    FINAL_OBSERVATION,
    HISTORY_END,
    MAX_GROUP_ROWS,
    NUMERIC_KINDS,
    TERMINATED,
    TRUNCATED,
    Layout,
    PathLike,
    ProblemLog,
    dims_text,
    inspect_layout,
    official_dtype,
    open_hdf5,
    step_num_breaks,
    translate_hdf5_errors,
)
from vintix.data.reader import LearningHistory
from vintix.errors import DatasetError

ExpectedDims = Callable[[str], tuple[int, int] | tuple[int, int, bool] | None]
"""task_name -> (obs_dim, act_dim) from the task registry, with ``True`` third for a discrete task (whose act_dim
is its number of actions; a pair is a continuous task), or None for a task it does not know."""
EpisodeLimit = Callable[[str], int | None]
"""task_name -> the most steps one of its episodes can have (the registry's episode length), or None."""


@dataclass(frozen=True)
class Problem:
    """One thing wrong with one file or folder of a dataset."""

    path: Path
    message: str

    def __str__(self) -> str:
        return f"{self.path}: {self.message}"


def validate_dataset(root: PathLike, expected_dims: ExpectedDims | None = None,
                     episode_limit: EpisodeLimit | None = None) -> list[Problem]:
    """Every problem of the dataset at ``root``; an empty list means it follows the official format."""
    try:
        folders = task_dirs(root)
    except DatasetError as err:
        return [Problem(err.path, err.problem)]
    if not folders:
        return [Problem(Path(root), "no <domain>/<task_dir>/ folders found; point to the dataset root "
                        "(layout: docs/data-format.md)")]
    return [problem for folder in folders for problem in validate_task(folder, expected_dims, episode_limit)]


def validate_task(task_dir: PathLike, expected_dims: ExpectedDims | None = None,
                  episode_limit: EpisodeLimit | None = None) -> list[Problem]:
    """Problems of one task folder: its JSON, leftovers of interrupted writes, and every history."""
    task_dir = Path(task_dir)
    problems: list[Problem] = []
    dims, task_name, limit, discrete = None, None, None, False
    try:
        meta = read_task_metadata(task_dir)
        register_dataset_task(task_dir, meta)  # its spec checked, and the registry's dims for it below
        dims, task_name, discrete = metadata_dims(meta), meta["task_name"], meta["action_type"] == "discrete"
        limit = episode_limit(task_name) if episode_limit else None
        expected = expected_dims(meta["task_name"]) if expected_dims else None
        registry = None if expected is None else (*expected[:2], len(expected) == 3 and bool(expected[2]))
        if registry is not None and registry != (*dims, discrete):
            problems.append(Problem(
                metadata_path(task_dir),
                f"task {meta['task_name']!r} declares {dims_text(*dims, discrete)} but the task registry expects "
                f"{dims_text(*registry, named=False)}; check the environment version (MuJoCo -v4 and -v5 dims "
                "differ) or fix the json",
            ))
    except DatasetError as err:
        problems.append(Problem(err.path, err.problem))
    problems += [Problem(p, "leftover of an interrupted write; delete it") for p in sorted(task_dir.glob("*.partial"))]
    histories, strays = history_entries(task_dir)
    problems += [Problem(p, NOT_A_HISTORY) for p in strays]
    if not histories:
        problems.append(Problem(task_dir, "no learning histories (*.h5); collect some or remove the folder"))
    for path in histories:
        problems += [Problem(path, message) for message in validate_history(path, dims, task_name, limit, discrete)]
    return problems


def task_mismatch(recorded: object, task: str | None) -> str | None:
    """Why a history that records task `recorded` cannot be one of `task`'s, or None: a file moved into
    another task's folder of the same dims would otherwise train as that task."""
    if task is None or recorded is None or recorded == task:
        return None
    return (f"was collected on task {recorded!r} but sits in the folder of task {task!r}; "
            f"move it to {recorded!r}'s folder")


def validate_history(path: PathLike, dims: tuple[int, int] | None = None, task: str | None = None,
                     episode_limit: int | None = None, discrete: bool = False) -> list[str]:
    """Problems of one history file; ``dims`` is the (obs_dim, act_dim) its task JSON declares (`discrete`: act_dim
    is the number of actions, and each row's action an index below it), `task` the task its folder holds (our files
    record the task they were collected on; published ones do not) and `episode_limit` the most steps an episode of
    that task can have."""
    path = Path(path)
    messages: list[str] = []
    try:
        with open_hdf5(path) as file, translate_hdf5_errors(path):
            layout = inspect_layout(file)
            messages += layout.problems
            messages += [m for m in [task_mismatch(file.attrs.get("task"), task)] if m]
            mismatch = None if dims is None else layout.mismatch(*dims, discrete)
            messages += [mismatch] if mismatch else []
            actions = dims[1] if dims is not None and discrete and mismatch is None else None
            messages += _check_contents(file, layout, episode_limit, actions)
    except DatasetError as err:
        messages.append(err.problem)
    return messages


def _check_contents(file: h5py.File, layout: Layout, episode_limit: int | None = None,
                    actions: int | None = None) -> list[str]:
    """Official dtypes, group sizes, finite values and step_num counting, group by group in step order
    (demonstrator actions, when the file has them, are checked like actions); a discrete history's actions
    must be indices below `actions` (its task's number of actions, when known)."""
    log = ProblemLog()
    recollect = "re-collect the history"
    rewrite = "rewrite it with LearningHistoryWriter, which casts to the official dtypes"
    action_names = ["action"] + [n for n in [layout.demonstrator_action] if n]
    # A discrete history's actions are integers, always finite: their range is what can be wrong.
    real_valued = (["proprio_observation", "reward"] if layout.discrete
                   else ["proprio_observation", "action", "reward", *action_names[1:]])
    previous_stop, last_step = 0, -1
    starts: list[np.ndarray] = []  # per group, where step_num is 0 (an episode starts)
    recorded: list[tuple[np.ndarray, np.ndarray] | None] = []  # per group, (absolute end rows, kinds) if stored
    for span in layout.groups:
        name, offset, rows = span.name, span.start, span.stop - span.start
        if rows == 0:  # the layout check already reported that its name promises rows
            continue
        group = file[name]
        if rows > MAX_GROUP_ROWS:
            log.add("size", f"group {name!r} holds {rows} rows, more than {MAX_GROUP_ROWS}", rewrite)
        stored = [*DTYPES, *action_names[1:]]
        for key in stored:
            if group[key].dtype != official_dtype(key, layout.discrete):
                expected = official_dtype(key, layout.discrete)
                where = f"{key} is {group[key].dtype} in group {name!r}, expected {expected}"
                log.add(f"dtype {key}", where, rewrite)
        if any(group[key].dtype.kind not in NUMERIC_KINDS for key in stored):
            continue  # values that are not numbers (bytes, strings) cannot be checked as numbers; reported above
        if layout.discrete and actions is not None:
            for key in action_names:
                values = group[key][()]
                outside = (values < 0) | (values >= actions)
                if outside.any():
                    log.add(f"range {key}", f"{key} {int(values[outside][0])} at row {offset + np.argmax(outside)} is "
                            f"outside the task's {actions} actions (0-{actions - 1})", recollect, int(outside.sum()))
        for key in real_valued:
            bad_rows = ~np.isfinite(group[key][()]).reshape(rows, -1).all(axis=1)
            if bad_rows.any():
                where = f"NaN/inf in {key} at row {offset + np.argmax(bad_rows)}"
                fix = f"the environment or policy diverged; {recollect}"
                log.add(f"finite {key}", where, fix, int(bad_rows.sum()))
        steps = group["step_num"][()]
        # Across a gap (already reported by the layout check) only the group's own rows can be checked.
        breaks = step_num_breaks(steps, last_step if offset == previous_stop else steps[0] - 1)
        if len(breaks) and offset == 0 and breaks[0] == 0:
            log.add("first step", f"starts at step_num {steps[0]}, expected 0 (a history starts with an episode)",
                    recollect)
            breaks = breaks[1:]
        if len(breaks):
            i = breaks[0]
            before = last_step if i == 0 else steps[i - 1]
            log.add(
                "step_num",
                f"step_num jumps from {before} to {steps[i]} at row {offset + i} (within an episode it must "
                "increase by 1; 0 starts a new episode)",
                recollect,
                len(breaks),
            )
        if episode_limit is not None and steps.max() >= episode_limit:
            first = int(np.argmax(steps >= episode_limit))
            log.add("episode length", f"step_num {int(steps[first])} at row {offset + first}: an episode longer than "
                    f"the task's {episode_limit} steps; the file is another task's, or its collection broke", recollect)
        previous_stop, last_step = span.stop, int(steps[-1])
        starts.append(offset + np.flatnonzero(steps == 0))
        recorded.append(_recorded_ends(group, name, offset, rows, layout.obs_dim, log))
    _check_ends(starts, recorded, layout.groups[-1].stop if layout.groups else 0, log)
    return log.messages()


def _recorded_ends(group: h5py.Group, name: str, offset: int, rows: int, obs_dim: int | None,
                   log: ProblemLog) -> tuple[np.ndarray, np.ndarray] | None:
    """The episode ends a group records (§3.6), as absolute rows and kinds, checked on their own."""
    present = [key for key in EPISODE_END_DATASETS if isinstance(group.get(key), h5py.Dataset)]
    if not present:
        return None
    fix = "re-collect the history, or delete the three episode-end datasets"
    if len(present) < len(EPISODE_END_DATASETS):
        log.add("episode ends", f"group {name!r} has {present} but not all of {list(EPISODE_END_DATASETS)}", fix)
        return None
    end_rows, kinds, final = (group[key][()] for key in EPISODE_END_DATASETS)
    if not (end_rows.ndim == kinds.ndim == 1 and len(end_rows) == len(kinds) == len(final)
            and final.shape[1:] == (obs_dim,)):
        log.add("episode ends", f"group {name!r}: {EPISODE_END_ROW} {end_rows.shape}, {EPISODE_END_KIND} "
                f"{kinds.shape} and {FINAL_OBSERVATION} {final.shape} do not match (k,), (k,), (k, {obs_dim})", fix)
        return None
    if (len(end_rows) and (end_rows.min() < 0 or end_rows.max() >= rows)) or np.any(np.diff(end_rows) <= 0):
        log.add("episode ends", f"group {name!r}: {EPISODE_END_ROW} must be increasing rows of the group", fix)
        return None
    if not np.isin(kinds, (TERMINATED, TRUNCATED, HISTORY_END)).all() or not np.isfinite(final).all():
        log.add("episode ends", f"group {name!r}: kinds outside {TERMINATED}-{HISTORY_END} or NaN/inf final "
                "observations", fix)
        return None
    return offset + end_rows, kinds


def _check_ends(starts: list[np.ndarray], recorded: list[tuple[np.ndarray, np.ndarray] | None], total: int,
                log: ProblemLog) -> None:
    """Recorded episode ends, when a file has them, are in every group and are exactly its episodes' last rows."""
    if all(r is None for r in recorded):
        return
    fix = "re-collect the history"
    if any(r is None for r in recorded):
        log.add("episode ends", "some groups record episode ends and others do not; a history records them in every "
                "group or in none", fix)
        return
    rows = np.concatenate([r[0] for r in recorded if r is not None])
    kinds = np.concatenate([r[1] for r in recorded if r is not None])
    expected = np.append(np.concatenate(starts)[1:] - 1, total - 1) if total else np.array([], int)
    if not np.array_equal(rows, expected):
        log.add("episode ends", f"the recorded episode ends ({len(rows)}) are not the rows where episodes end by "
                f"step_num ({len(expected)})", fix)
    elif (kinds[:-1] == HISTORY_END).any():
        log.add("episode ends", "an episode before the history's last is recorded as cut by the history's end", fix)


@dataclass(frozen=True)
class TaskSummary:
    """Size of one task's data, for ``vintix data stats``."""

    domain: str
    task_name: str
    histories: int
    steps: int
    episodes: int
    mean_episode_length: float
    """steps / episodes (NaN without episodes)."""
    return_by_episode: np.ndarray
    """the mean return of each history's i-th episode, over the histories that have one (how the histories
    improve: a check of a demonstrator; the format stores no success flag)"""


def summarize_dataset(root: PathLike) -> list[TaskSummary]:
    """Per-task counts and returns by episode index, reading the step_num and reward columns of each history; run
    validation first."""
    summaries = []
    for task in find_tasks(root):
        steps = 0
        returns = []
        for path in task.history_paths:
            with LearningHistory(path) as history:
                steps += history.num_steps
                returns.append(history.episode_returns())
        episodes = sum(len(r) for r in returns)
        mean_length = steps / episodes if episodes else float("nan")
        summaries.append(TaskSummary(task.domain, task.task_name, len(task.history_paths), steps, episodes,
                                     mean_length, _mean_by_index(returns)))
    return summaries


def _mean_by_index(series: list[np.ndarray]) -> np.ndarray:
    """Element i: the mean of ``s[i]`` over the series long enough to have one."""
    longest = max((len(s) for s in series), default=0)
    padded = np.full((len(series), longest), np.nan)
    for row, values in zip(padded, series, strict=True):
        row[: len(values)] = values
    return np.nanmean(padded, axis=0) if longest else np.zeros(0)  # every column has a value: no empty mean
