"""Learning histories in the official Vintix on-disk format (HDF5 + one JSON per task).

The specification, with every field, dtype, attribute and rule: docs/data-format.md.

Layout (compatible with the released Vintix dataset)::

    <root>/<domain>/<task_dir>/<task_dir>.json   # task_name, observation_shape.proprio=[d], action_dim, action_type
    <root>/<domain>/<task_dir>/*.h5              # one file per learning history

A history file holds groups of at most 10,000 consecutive steps named ``"<start>-<end>"`` (end
inclusive), each with ``proprio_observation`` float32 (n, obs_dim), ``action`` float32 (n, act_dim),
``reward`` float32 (n,) and ``step_num`` int32 (n,). Row i is (o_i, a_i taken at o_i, r_i after a_i);
``step_num == 0`` marks an episode start and a file starts with one.

**Discrete actions** (our extension; the release is continuous only): a task whose JSON says ``action_type:
"discrete"`` stores ``action`` as int32 (n,), one index in [0, action_dim) per row, where ``action_dim`` is the
number of actions of its ``Discrete`` space.

Optionally a group also holds ``demonstrator_action`` float32 (n, act_dim): the action the demonstrator
proposed at o_i before noise was mixed in (the field the Vintix II dataset adds; its loader also reads
the spellings ``expert_action`` and ``demonstrator_actions``, and so do we). Files without it, such as
the published Vintix dataset, read and validate as before.

Our writer stores every dataset in chunks of whole rows with HDF5's Fletcher-32 checksum filter, so
a block damaged on disk fails to read (a `DatasetError` naming the file) instead of feeding wrong
numbers to training. Chunking and filters are invisible to readers of the official format, and files
without checksums (the published dataset) read as before.
"""

from __future__ import annotations

import json
import math
import os
import re
from bisect import bisect_right
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from itertools import takewhile
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from vintix.atomic import atomic_write_text, make_parent_dirs, new_partial_file, os_error_in, publish
from vintix.errors import DatasetError, VintixError, json_loads
from vintix.tasks.custom import register_specs
from vintix.tasks.registry import TaskSpec

MAX_GROUP_ROWS = 10_000
"""Most rows a step group may hold in the official format."""

CHECKSUM_CHUNK_ROWS = 1_000
"""Rows per checksummed HDF5 chunk: a training window (~1,000 rows) touches one or two chunks per
dataset, and a damaged byte makes only its own chunk unreadable."""

DTYPES: dict[str, np.dtype] = {
    "proprio_observation": np.dtype(np.float32),
    "action": np.dtype(np.float32),
    "reward": np.dtype(np.float32),
    "step_num": np.dtype(np.int32),
}
"""Dataset name in a group -> official dtype."""
NUMERIC_KINDS = "fiub"
"""numpy dtype kinds a step dataset may be stored as and still be read (cast to the official dtype)"""

FIELDS: dict[str, str] = {
    "observation": "proprio_observation",
    "action": "action",
    "reward": "reward",
    "step_num": "step_num",
}
"""Key returned by `LearningHistory.read` -> dataset name on disk."""

DEMONSTRATOR_ACTION = "demonstrator_action"
"""Optional dataset, float32 (n, act_dim): the demonstrator's action before noise, per row."""

DEMONSTRATOR_ACTION_SPELLINGS = (DEMONSTRATOR_ACTION, "demonstrator_actions", "expert_action")

DISCRETE_ACTION_DTYPE = np.dtype(np.int32)
"""The dtype of a discrete task's actions (and demonstrator actions): int32 (n,), one index per row."""
ACTION_TYPES = ("continuous", "discrete")
"""A task JSON's ``action_type``: the release's 'continuous', or our extension 'discrete'."""

EPISODE_END_ROW, EPISODE_END_KIND, FINAL_OBSERVATION = "episode_end_row", "episode_end_kind", "final_observation"
"""Optional per-group datasets (§3.6 of docs/data-format.md): the rows that end an episode, how each ended,
and the observation the env returned after it, which a row-per-step history otherwise never stores"""
TERMINATED, TRUNCATED, HISTORY_END = 1, 2, 3
"""How an episode ended: the env terminated it, its time limit truncated it, or the history stopped"""
EPISODE_END_DATASETS = (EPISODE_END_ROW, EPISODE_END_KIND, FINAL_OBSERVATION)
"""Names under which histories store it (ours first, then the other names the Vintix II loader reads)."""


def official_dtype(dataset: str, discrete: bool = False) -> np.dtype:
    """The dtype of a dataset of a step group; demonstrator actions, under any spelling, are actions, and a discrete
    history's actions are int32."""
    if discrete and dataset not in ("proprio_observation", "reward", "step_num"):
        return DISCRETE_ACTION_DTYPE
    return DTYPES.get(dataset, DTYPES["action"])


def dims_text(obs_dim: int, act_dim: int, discrete: bool, named: bool = True) -> str:
    """``(obs_dim, act_dim) = (3, 2)``, or for a discrete task ``(obs_dim, actions) = (2, 5) with action_type
    'discrete'``: how errors name a task's or a file's dims; without the names (`named` False) from ``(3, 2)`` on."""
    names = "(obs_dim, actions) = " if discrete else "(obs_dim, act_dim) = "
    kind = " with action_type 'discrete'" if discrete else ""
    return f"{names if named else ''}({obs_dim}, {act_dim}){kind}"


def is_action_dataset(dataset: str) -> bool:
    """Whether `dataset` holds actions (the executed ones, or the demonstrator's under any spelling)."""
    return dataset == "action" or dataset in DEMONSTRATOR_ACTION_SPELLINGS

PathLike = str | os.PathLike[str]

_GROUP_NAME = re.compile(r"(\d+)-(\d+)")
# h5py surfaces HDF5 failures (truncated or overwritten bytes) as OSError or RuntimeError.
_HDF5_FAILURES = (OSError, RuntimeError)


# --------------------------------------------------------------------------------------------
# Shared low-level helpers


@contextmanager
def translate_hdf5_errors(path: Path) -> Iterator[None]:
    """Turn HDF5 library failures, raised deep inside h5py, into a DatasetError that names the file.

    A block that fails its Fletcher-32 checksum surfaces here too (h5py raises OSError, "filter
    returned failure during read"), like a truncated file or overwritten metadata.
    """
    try:
        yield
    except BlockingIOError as err:  # HDF5's own file lock: another process holds the file open for writing
        raise DatasetError(path, f"another process has it open for writing ({err}), e.g. a collection still running; "
                                 "the file is not damaged: wait for that process to end") from err
    except PermissionError as err:
        raise DatasetError(path, f"no permission to read it ({err}); the file is not damaged: give your user read "
                                 "access (chmod u+r)") from err
    except _HDF5_FAILURES as err:
        # HDF5 reports a failed checksum (or decompression) only as a filter failure.
        what = ("a data block failed its checksum (corrupted on disk)" if "filter returned failure" in str(err)
                else "not a readable HDF5 file (truncated or corrupted?)")
        raise DatasetError(path, f"{what}: {err}; re-collect or delete it") from err


def open_hdf5(path: PathLike) -> h5py.File:
    """Open a history read-only, with errors a user can act on instead of an h5py traceback."""
    path = Path(path)
    if not path.is_file():
        raise DatasetError(path, "no such file; check the path (histories end in .h5)")
    with translate_hdf5_errors(path):
        return h5py.File(path, "r")


def step_num_breaks(step_num: np.ndarray, previous: int) -> np.ndarray:
    """Indices where ``step_num`` is neither 0 (an episode start) nor the previous value + 1.

    ``previous`` is the step number of the row just before ``step_num[0]``; pass -1 for the first
    row of a file, which therefore has to be 0.
    """
    steps = np.asarray(step_num, dtype=np.int64)
    before = np.concatenate(([previous], steps[:-1]))
    return np.flatnonzero((steps != 0) & (steps != before + 1))


class ProblemLog:
    """Collects problems by kind, so a file with 10,000 NaN rows yields one line, not 10,000."""

    def __init__(self) -> None:
        self._first: dict[str, tuple[str, str]] = {}
        self._count: Counter[str] = Counter()

    def add(self, kind: str, what: str, fix: str, count: int = 1) -> None:
        """Record ``count`` occurrences of ``kind``; only the first ``what`` is kept as the example."""
        self._first.setdefault(kind, (what, fix))
        self._count[kind] += count

    def messages(self) -> list[str]:
        """One message per kind: the first occurrence, how many there were, and the fix."""
        return [
            f"{what}{f' ({self._count[kind]} occurrences in this file)' if self._count[kind] > 1 else ''}; {fix}"
            for kind, (what, fix) in self._first.items()
        ]


# --------------------------------------------------------------------------------------------
# Group layout: the part of a file the reader needs to address rows


@dataclass(frozen=True)
class GroupSpan:
    """One step group of a history file: rows [start, stop) of the history."""

    name: str
    start: int
    stop: int


@dataclass
class Layout:
    """Groups sorted by start step, the dims they agree on, and what is wrong with them."""

    groups: list[GroupSpan]
    obs_dim: int | None
    act_dim: int | None
    """action channels of a continuous history; None for a discrete one (its file does not say how many actions
    there are: its task JSON does) or where groups disagree"""
    problems: list[str]
    demonstrator_action: str | None = None
    """On-disk name of the demonstrator actions, which every group holds; None if the file has none."""
    discrete: bool = False
    """whether the history stores discrete actions: integer (n,) where a continuous one stores float (n, act_dim)"""

    def mismatch(self, obs_dim: int, act_dim: int, discrete: bool) -> str | None:
        """Why this history cannot be one of a task with these dims and kind of action, or None."""
        if self.obs_dim is None:
            return None  # groups that disagree: reported as a problem of their own
        kind = "discrete" if self.discrete else "continuous"
        if self.discrete != discrete:
            return (f"holds {kind} actions but its task is {'discrete' if discrete else 'continuous'} (its JSON's "
                    "action_type); the file belongs to another task, or the json is wrong")
        held = (self.obs_dim, self.act_dim) if not discrete else (self.obs_dim,)
        declared = (obs_dim, act_dim) if not discrete else (obs_dim,)
        if held != declared:
            what = "(obs_dim, act_dim)" if not discrete else "(obs_dim,)"
            return (f"holds {what} = {held} but the task json declares {declared}; the file belongs to another task, "
                    "or the json is wrong")
        return None


def parse_group_name(name: str) -> tuple[int, int] | None:
    """``"10000-19999"`` -> (10000, 19999); None if the name is not ``"<start>-<end>"`` with end >= start."""
    match = _GROUP_NAME.fullmatch(name)
    if match is None:
        return None
    start, end = int(match[1]), int(match[2])
    return (start, end) if end >= start else None


_REBUILD = "re-collect or delete the file"


def demonstrator_action_name(group: h5py.Group) -> str | None:
    """The spelling under which a step group stores demonstrator actions, or None."""
    return next((name for name in DEMONSTRATOR_ACTION_SPELLINGS if isinstance(group.get(name), h5py.Dataset)), None)


def _group_shape(name: str, group: h5py.Group, log: ProblemLog) -> tuple[int, int, int | None] | None:
    """(rows, obs_dim, act_dim) of a step group (act_dim None: discrete actions, integers of shape (n,)), or None
    (with the problem logged) if it is unusable."""
    datasets = {key: group.get(key) for key in DTYPES}
    missing = [key for key, ds in datasets.items() if not isinstance(ds, h5py.Dataset)]
    if missing:
        log.add("missing", f"group {name!r} lacks dataset(s) {missing}", _REBUILD)
        return None
    obs, act, rew, step = (datasets[key].shape for key in DTYPES)
    discrete = len(act) == 1 and datasets["action"].dtype.kind in "iu"
    if len(act) == 1 and not discrete:
        log.add("discrete action dtype", f"group {name!r} stores one action per row as {datasets['action'].dtype}: "
                "a discrete task's actions are integer indices (int32)", _REBUILD)
        return None
    ranks_ok = len(obs) == 2 and len(act) == (1 if discrete else 2) and len(rew) == len(step) == 1
    if not (ranks_ok and obs[0] == act[0] == rew[0] == step[0]):
        log.add(
            "shape",
            f"group {name!r} has dataset shapes obs {obs}, action {act}, reward {rew}, step_num {step}; "
            "expected (n, obs_dim), (n, act_dim) (a discrete task: integer (n,)), (n,), (n,)",
            _REBUILD,
        )
        return None
    unwritten = [key for key, ds in datasets.items() if _declares_unwritten_rows(ds)]
    if unwritten:
        log.add("unwritten", f"group {name!r} declares {step[0]:,} rows but stores no data for some of them in "
                f"{unwritten} (a write that never finished, or a file that only claims its size)", _REBUILD)
        return None
    demonstrator = demonstrator_action_name(group)
    if demonstrator is not None and group[demonstrator].shape != act:
        log.add("demonstrator shape", f"group {name!r} has {demonstrator} of shape {group[demonstrator].shape}, "
                f"expected the action's {act}", _REBUILD)
        return None
    return step[0], obs[1], None if discrete else act[1]


def _declares_unwritten_rows(dataset: h5py.Dataset) -> bool:
    """Whether part of `dataset`'s shape was never stored: a chunk never written, or contiguous storage
    smaller than the shape. HDF5 reads such rows as fill values without complaint, and a file of a few KB
    may so declare 10^9 rows, which a reader would try to allocate. Metadata only: no data is read."""
    if dataset.size == 0 or dataset.is_virtual or dataset.external:
        return False
    if dataset.chunks is None:
        return dataset.id.get_storage_size() < dataset.nbytes
    chunks = math.prod(math.ceil(n / c) for n, c in zip(dataset.shape, dataset.chunks, strict=True))
    return dataset.id.get_num_chunks() < chunks


def inspect_layout(file: h5py.File) -> Layout:
    """Index the step groups of an open history from metadata only (no row data is read).

    Checks what row addressing depends on: group names, datasets present with matching row
    counts and consistent dims, names agreeing with row counts, and groups contiguous from 0.
    Groups are ordered by their parsed start step: HDF5 lists names lexicographically, which
    puts "100-109" before "20-29".
    """
    log = ProblemLog()
    groups: list[GroupSpan] = []
    claimed: list[GroupSpan] = []  # usable groups plus broken ones by name, so a broken group is not also a gap
    dims: set[tuple[int, int | None]] = set()
    demonstrator_names: set[str | None] = set()
    for name, item in file.items():
        span = parse_group_name(name)
        if span is None or not isinstance(item, h5py.Group):
            log.add("name", f"entry {name!r} is not a step group named '<start>-<end>'", f"remove it or {_REBUILD}")
            continue
        shape = _group_shape(name, item, log)
        if shape is None:
            claimed.append(GroupSpan(name, span[0], span[1] + 1))
            continue
        rows, obs_dim, act_dim = shape
        if span[1] - span[0] + 1 != rows:
            log.add("rows", f"group {name!r} is named for {span[1] - span[0] + 1} steps but holds {rows}", _REBUILD)
        dims.add((obs_dim, act_dim))
        demonstrator_names.add(demonstrator_action_name(item))
        groups.append(GroupSpan(name, span[0], span[0] + rows))
        claimed.append(groups[-1])
    if len(dims) > 1:
        shown = sorted(dims, key=str)
        log.add("dims", f"groups disagree on (obs_dim, act_dim) (None: discrete): {shown}",
                f"it mixes tasks; {_REBUILD}")
    if len(demonstrator_names) > 1:
        found = sorted(str(n) for n in demonstrator_names)
        log.add("demonstrator", f"groups disagree on their demonstrator-action dataset ({', '.join(found)}); a history "
                "stores it in every group under one name or in none", _REBUILD)
    expected_start = 0
    for group in sorted(claimed, key=lambda g: g.start):
        if group.start != expected_start:
            kind = "gap" if group.start > expected_start else "overlap"
            where = f"{kind} before group {group.name!r}: expected a group starting at step {expected_start}"
            log.add("contiguity", where, _REBUILD)
        expected_start = group.stop
    if not claimed and not log.messages():
        log.add("empty", "contains no step groups", "delete it")
    groups.sort(key=lambda g: g.start)
    agreed_obs_dim, agreed_act_dim = next(iter(dims)) if len(dims) == 1 else (None, None)
    demonstrator = next(iter(demonstrator_names)) if len(demonstrator_names) == 1 else None
    discrete = len(dims) == 1 and agreed_act_dim is None
    return Layout(groups, agreed_obs_dim, agreed_act_dim, log.messages(), demonstrator, discrete)


# --------------------------------------------------------------------------------------------
# Size on disk

GROUP_METADATA_BYTES = 24_000
"""HDF5 metadata per step group (measured on our files: size minus allocated chunks; 7,900 of it for the
three episode-end datasets, docs/data-format.md §3.6)."""
ROOT_ATTRIBUTE_BYTES = 4_300
"""The root attributes that say how a history was made (task, seeds, schedule): they overflow the root
group's header into a block of their own (measured: files of 250 to 12,345 steps are 4,220-4,300 bytes
larger than their chunks and group metadata)."""


def history_bytes(spec: TaskSpec, steps: int) -> int:
    """Size on disk of one history of `steps` rows of `spec`; episodes are counted as running their full
    length, so a task whose episodes end early writes 5 + 4·obs_dim bytes more per extra episode."""
    row = 4 * (spec.obs_dim + 2 * spec.act_dim + 2)
    # A group's chunks hold min(rows, CHECKSUM_CHUNK_ROWS) rows each, the last one allocated whole.
    def allocated(rows: int) -> int:
        return rows if rows < CHECKSUM_CHUNK_ROWS else math.ceil(rows / CHECKSUM_CHUNK_ROWS) * CHECKSUM_CHUNK_ROWS

    full, rest = divmod(steps, MAX_GROUP_ROWS)  # closed form: a 10^12-step plan is priced in no time
    allocated_rows = full * allocated(MAX_GROUP_ROWS) + (allocated(rest) if rest else 0)
    # Each episode end: its row, its kind and the observation after it; at least one per episode_length steps.
    episode_ends = math.ceil(steps / spec.episode_length) * (4 + 1 + 4 * spec.obs_dim)
    return (row * allocated_rows + episode_ends + GROUP_METADATA_BYTES * math.ceil(steps / MAX_GROUP_ROWS)
            + ROOT_ATTRIBUTE_BYTES)



# --------------------------------------------------------------------------------------------
# Writer


UNFINISHED_FILES: set[Path] = set()
"""The partial files of this process's open writers: what a process ended by a signal deletes on its
way out (`vintix.collect` workers), since it does not unwind through the writers."""


@contextmanager
def _write_errors_as_os_errors(path: Path) -> Iterator[None]:
    """HDF5's failed writes as the OSError of the system call that failed (a full disk is ENOSPC), naming
    `path`: h5py raises some of them as RuntimeErrors that carry the errno only in their text."""
    try:
        yield
    except (OSError, RuntimeError) as error:
        if isinstance(error, OSError) and error.errno is not None:
            raise OSError(error.errno, os.strerror(error.errno), str(path)) from error
        translated = os_error_in(error, r"errno = (\d+)", path)
        if translated is None:
            raise
        raise translated from error


class LearningHistoryWriter:
    """Writes one learning history in the official format, atomically.

    Rows go to ``<name>.h5.<random>.partial`` and the file is renamed to ``<name>.h5`` only by a successful
    ``close()``, so an interrupted run never leaves a file that looks whole. If the ``with`` block
    raises, the partial file is deleted rather than kept: the writer cannot resume it (buffered rows
    are lost with the process), so it would only waste disk; a .partial left by a hard kill is
    ignored by `find_tasks` and reported by validation. An existing ``<name>.h5`` is replaced on
    close, like any atomic save.

    Example::

        with LearningHistoryWriter(path, obs_dim=17, act_dim=6) as writer:
            writer.append(obs, action, reward, step_num)       # one step, or a batch of rows

    ``attrs`` become root attributes of the file (e.g. ``env_seed``, which says which env, and so
    which Meta-World hidden goal, the history was collected on); readers of the official format
    ignore them. With ``demonstrator_actions=True`` every append also takes the demonstrator's
    action before noise, stored as the optional ``demonstrator_action`` dataset. With ``discrete=True`` the task
    has `act_dim` discrete actions: each row's action is one integer index in [0, act_dim), stored as int32 (n,).
    """

    def __init__(self, path: PathLike, obs_dim: int, act_dim: int, chunk_size: int = MAX_GROUP_ROWS,
                 attrs: dict[str, int | float | str | list[float]] | None = None,
                 demonstrator_actions: bool = False, episode_ends: bool = False, discrete: bool = False) -> None:
        self.path = Path(path)
        if self.path.suffix != ".h5":
            raise DatasetError(self.path, "history files must end in .h5 (find_tasks looks for *.h5); rename it")
        if not (_is_dim(obs_dim) and _is_dim(act_dim)):
            raise DatasetError(self.path,
                               f"obs_dim and act_dim must be positive integers, got {obs_dim!r} and {act_dim!r}")
        if not (_is_dim(chunk_size) and chunk_size <= MAX_GROUP_ROWS):
            raise DatasetError(self.path, f"chunk_size must be in [1, {MAX_GROUP_ROWS}] (official group limit), got "
                               f"{chunk_size!r}")
        self.obs_dim, self.act_dim, self.chunk_size, self.discrete = obs_dim, act_dim, chunk_size, discrete
        # Rows wait in fixed buffers of one group, so single-step appends cost a copy, not an HDF5 write.
        self._action_shape: tuple[int, ...] = () if discrete else (act_dim,)
        trailing = {"proprio_observation": (obs_dim,), "action": self._action_shape, "reward": (), "step_num": ()}
        self._buffer = {key: np.empty((chunk_size, *trailing[key]), official_dtype(key, discrete))
                        for key in DTYPES}
        self.demonstrator_actions = demonstrator_actions
        if demonstrator_actions:
            self._buffer[DEMONSTRATOR_ACTION] = np.empty((chunk_size, *self._action_shape),
                                                         official_dtype(DEMONSTRATOR_ACTION, discrete))
        self.episode_ends = episode_ends
        if episode_ends:  # per row here; only the rows that end an episode are written (`_flush`)
            self._buffer[EPISODE_END_KIND] = np.empty(chunk_size, np.int8)
            self._buffer[FINAL_OBSERVATION] = np.empty((chunk_size, obs_dim), DTYPES["proprio_observation"])
        self._filled = 0
        self._flushed = 0
        self._last_step = -1
        make_parent_dirs(self.path)
        self._partial = new_partial_file(self.path)
        UNFINISHED_FILES.add(self._partial)
        # No chunk cache: each chunk reaches the disk inside the call that writes it, so a full disk is an
        # OSError there, not a write HDF5 retries when it frees the dataset (errors it can only print,
        # then a segfault).
        self._file: h5py.File | None = None
        try:  # a disk that fills up can fail these first writes too: then no partial file may stay behind
            with _write_errors_as_os_errors(self._partial):
                self._file = h5py.File(self._partial, "w", rdcc_nbytes=0)
                self._file.attrs.update(attrs or {})
        except BaseException:
            self.abort()
            raise

    @property
    def num_steps(self) -> int:
        """Rows appended so far (written or buffered)."""
        return self._flushed + self._filled

    def append(self, obs: Any, action: Any, reward: Any, step_num: Any, demonstrator_action: Any = None,
               episode_end: Any = None, final_observation: Any = None) -> None:
        """Append one step (1-D obs/action, scalar reward/step_num) or a batch (2-D obs/action, 1-D rest).

        Everything is checked before anything is buffered, so a rejected call leaves the writer
        unchanged: shapes against obs_dim/act_dim, numeric dtypes (integer step_num), finite values,
        and step_num counting 0, 1, 2, ... within episodes starting from 0 at the file's first row.
        `demonstrator_action` (shaped like `action`) is required by a writer made with
        ``demonstrator_actions=True`` and refused by one without. A writer made with ``episode_ends=True``
        takes per row `episode_end` (0, or TERMINATED / TRUNCATED / HISTORY_END where the row ends an
        episode) and `final_observation` (shaped like `obs`; read only where `episode_end` is not 0).
        """
        if self._file is None:
            raise DatasetError(self.path, "append() after close() or abort(); open a new writer")
        if (demonstrator_action is None) == self.demonstrator_actions:
            made = "with" if self.demonstrator_actions else "without"
            raise DatasetError(self.path, f"this writer was made {made} demonstrator_actions, so append() "
                               f"{'needs' if self.demonstrator_actions else 'takes no'} demonstrator_action")
        if (episode_end is None or final_observation is None) == self.episode_ends:
            made = "with" if self.episode_ends else "without"
            raise DatasetError(self.path, f"this writer was made {made} episode_ends, so append() "
                               f"{'needs' if self.episode_ends else 'takes no'} episode_end and final_observation")
        rows = self._checked_rows(obs, action, reward, step_num, demonstrator_action)
        if self.episode_ends:
            rows |= self._checked_ends(episode_end, final_observation, len(rows["step_num"]))
        n, offset = len(rows["step_num"]), 0
        while offset < n:
            take = min(n - offset, self.chunk_size - self._filled)
            for key, values in rows.items():
                self._buffer[key][self._filled : self._filled + take] = values[offset : offset + take]
            self._filled += take
            offset += take
            if self._filled == self.chunk_size:
                self._flush()
        if n:
            self._last_step = int(rows["step_num"][-1])

    def _checked_rows(self, obs: Any, action: Any, reward: Any, step_num: Any,
                      demonstrator_action: Any) -> dict[str, np.ndarray]:
        given = {"observation": np.asarray(obs), "action": np.asarray(action),
                 "reward": np.asarray(reward), "step_num": np.asarray(step_num)}
        disk_names = dict(FIELDS)
        if demonstrator_action is not None:
            given[DEMONSTRATOR_ACTION] = np.asarray(demonstrator_action)
            disk_names[DEMONSTRATOR_ACTION] = DEMONSTRATOR_ACTION
        single = given["observation"].ndim == 1
        lead = () if single else given["observation"].shape[:1]
        expected = {"observation": (*lead, self.obs_dim), "action": (*lead, *self._action_shape),
                    "reward": lead, "step_num": lead, DEMONSTRATOR_ACTION: (*lead, *self._action_shape)}
        for name, values in given.items():
            if values.shape != expected[name]:
                kind = (f"{self.act_dim} discrete actions: one integer per step" if self.discrete
                        else f"act_dim={self.act_dim}")
                raise DatasetError(
                    self.path,
                    f"append() got {name} of shape {values.shape}, expected {expected[name]} "
                    f"(obs_dim={self.obs_dim}, {kind}; one step: 1-D observation, batch: 2-D)",
                )
            integer = name == "step_num" or (self.discrete and is_action_dataset(name))
            wanted = ("iu", "an integer") if integer else ("iuf", "a real")
            if values.dtype.kind not in wanted[0]:
                why = " (a discrete task's actions are indices)" if integer and name != "step_num" else ""
                raise DatasetError(self.path, f"append() got {name} of dtype {values.dtype}, expected {wanted[1]} "
                                   f"one{why}")
            if name != "step_num" and not np.isfinite(values).all():
                raise DatasetError(
                    self.path, f"append() got NaN/inf in {name}; the environment or policy diverged, fix it first"
                )
            outside = values.size and not (0 <= values.min() and values.max() < self.act_dim)
            if integer and name != "step_num" and outside:
                raise DatasetError(self.path, f"append() got {name} {int(values.min())}..{int(values.max())}, outside "
                                   f"the task's {self.act_dim} actions 0-{self.act_dim - 1}")
        rows = {disk: (given[key][None] if single else given[key]).astype(official_dtype(disk, self.discrete))
                for key, disk in disk_names.items()}
        breaks = step_num_breaks(rows["step_num"], self._last_step)
        if len(breaks):
            i = breaks[0]
            before = self._last_step if i == 0 else rows["step_num"][i - 1]
            raise DatasetError(
                self.path,
                f"append() got step_num {rows['step_num'][i]} after {before} (row {self.num_steps + i}); "
                "step_num must count 0, 1, 2, ... within an episode and the file must start at 0",
            )
        return rows

    def _checked_ends(self, episode_end: Any, final_observation: Any, n: int) -> dict[str, np.ndarray]:
        kinds = np.asarray(episode_end).reshape(-1)
        final = np.asarray(final_observation, dtype=np.float64).reshape(-1, self.obs_dim)
        if kinds.shape != (n,) or final.shape != (n, self.obs_dim):
            raise DatasetError(self.path, f"append() got episode_end of shape {kinds.shape} and final_observation of "
                               f"shape {final.shape} for {n} rows")
        if not np.isin(kinds, (0, TERMINATED, TRUNCATED, HISTORY_END)).all():
            raise DatasetError(self.path, f"episode_end must be 0, {TERMINATED}, {TRUNCATED} or {HISTORY_END}, got "
                               f"{sorted(set(kinds.tolist()))}")
        if not np.isfinite(final[kinds > 0]).all():
            raise DatasetError(self.path, "append() got NaN/inf in a final_observation; the environment diverged")
        return {EPISODE_END_KIND: kinds.astype(np.int8), FINAL_OBSERVATION: final.astype(np.float32)}

    def _flush(self) -> None:
        with _write_errors_as_os_errors(self._partial):
            self._write_group()

    def _write_group(self) -> None:
        assert self._file is not None
        start, n = self._flushed, self._filled
        group = self._file.create_group(f"{start}-{start + n - 1}")
        for key, buffer in self._buffer.items():
            if key in (EPISODE_END_KIND, FINAL_OBSERVATION):
                continue
            rows = buffer[:n]
            # fletcher32 needs a chunked layout; chunks of whole rows keep row-range reads cheap.
            group.create_dataset(key, data=rows, chunks=(min(n, CHECKSUM_CHUNK_ROWS), *rows.shape[1:]),
                                 fletcher32=True)
        if self.episode_ends:
            ends = np.flatnonzero(self._buffer[EPISODE_END_KIND][:n])
            for key, values in ((EPISODE_END_ROW, ends.astype(np.int32)),
                                (EPISODE_END_KIND, self._buffer[EPISODE_END_KIND][ends]),
                                (FINAL_OBSERVATION, self._buffer[FINAL_OBSERVATION][ends])):
                # Resizable only so that a group with no episode end can still hold a (checksummed) empty chunk.
                group.create_dataset(key, data=values, fletcher32=True, chunks=(max(1, len(values)), *values.shape[1:]),
                                     maxshape=(None, *values.shape[1:]))
        self._flushed += n
        self._filled = 0

    def close(self) -> Path:
        """Write the last (possibly short) group and atomically publish the file; returns its path."""
        if self._file is None:
            return self.path
        try:
            if self._filled:
                self._flush()
            if self._flushed == 0:
                raise DatasetError(self.path, "no steps were appended, so no file was written; append before close()")
            with _write_errors_as_os_errors(self._partial):
                self._file.close()
            publish(self._partial, self.path)
        except BaseException:
            self.abort()
            raise
        self._file = None
        UNFINISHED_FILES.discard(self._partial)
        return self.path

    def abort(self) -> None:
        """Discard everything written so far (the final file never appears)."""
        file, self._file = self._file, None
        try:
            if file is not None:
                file.close()
        except (OSError, RuntimeError):  # its last writes failed (a full disk): the file is being discarded
            pass
        finally:  # whatever closing raised, the partial file goes
            self._partial.unlink(missing_ok=True)
            UNFINISHED_FILES.discard(self._partial)

    def __enter__(self) -> LearningHistoryWriter:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


# --------------------------------------------------------------------------------------------
# Reader


class LearningHistory:
    """Lazy, fork-safe reader of one history file.

    The HDF5 handle is opened on first use and re-opened whenever ``os.getpid()`` changed: HDF5
    handles must not be shared across a fork, and forked ``DataLoader`` workers inherit this object.
    Pickling drops the handle too (spawned workers). Reads touch only the slices they need.
    """

    def __init__(self, path: PathLike) -> None:
        self.path = Path(path)
        self._handle: h5py.File | None = None
        self._pid: int | None = None
        self._layout: Layout | None = None
        self._episode_starts: np.ndarray | None = None
        self._episode_returns: np.ndarray | None = None

    @property
    def _file(self) -> h5py.File:
        if self._handle is None or self._pid != os.getpid():
            # A handle inherited through fork is replaced, never used: HDF5 state is not fork-safe.
            self._handle, self._pid = open_hdf5(self.path), os.getpid()
        return self._handle

    @property
    def layout(self) -> Layout:
        """The file's groups in step order (checked once; a file that cannot be indexed raises)."""
        if self._layout is None:
            with translate_hdf5_errors(self.path):
                layout = inspect_layout(self._file)
            if layout.problems:
                raise DatasetError(self.path, "; ".join(layout.problems))
            self._layout = layout
        return self._layout

    @property
    def attrs(self) -> dict[str, Any]:
        """The file's root attributes as Python values (our writer's ``attrs``; published files have none)."""
        with translate_hdf5_errors(self.path):
            return {key: value.item() if isinstance(value, np.generic) else value
                    for key, value in self._file.attrs.items()}

    @property
    def env_seed(self) -> int | None:
        """Seed of the env the history was collected on (our files), None for files without it."""
        seed = self.attrs.get("env_seed")
        return None if seed is None else int(seed)

    @property
    def num_steps(self) -> int:
        """Rows in the history."""
        return self.layout.groups[-1].stop

    @property
    def obs_dim(self) -> int:
        """Observation size (``proprio_observation`` columns)."""
        assert self.layout.obs_dim is not None
        return self.layout.obs_dim

    @property
    def act_dim(self) -> int | None:
        """Action channels; None for a discrete history (its task JSON says how many actions there are)."""
        return self.layout.act_dim

    @property
    def discrete(self) -> bool:
        """Whether the history stores discrete actions (int32 indices)."""
        return self.layout.discrete

    @property
    def has_demonstrator_action(self) -> bool:
        """Whether the file stores the demonstrator's action before noise (any accepted spelling)."""
        return self.layout.demonstrator_action is not None

    def __len__(self) -> int:
        return self.num_steps

    def _column(self, name: str) -> np.ndarray:
        """One dataset over the whole history (1-D columns only: a few bytes per step)."""
        with translate_hdf5_errors(self.path):
            return np.concatenate([self._file[g.name][name][()] for g in self.layout.groups])

    @property
    def episode_starts(self) -> np.ndarray:
        """Row indices where ``step_num == 0`` (cached)."""
        if self._episode_starts is None:
            self._episode_starts = np.flatnonzero(self._column("step_num") == 0)
        return self._episode_starts

    def episode_returns(self) -> np.ndarray:
        """Sum of rewards of each episode, in order (the last one may be cut short by the history's end);
        cached and read-only, since plots and schedule fits ask for it more than once per file."""
        if self._episode_returns is None:
            starts = self.episode_starts
            if len(starts) == 0 or starts[0] != 0:
                raise DatasetError(
                    self.path, "does not start with step_num 0, so episodes are ambiguous; run `vintix data validate`"
                )
            self._episode_returns = np.add.reduceat(self._column("reward").astype(np.float64), starts)
            self._episode_returns.flags.writeable = False
        return self._episode_returns

    def episode_lengths(self) -> np.ndarray:
        """Steps of each episode, in the order of `episode_returns`."""
        return np.diff(np.append(self.episode_starts, self.num_steps))

    def episode_ends(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The episode ends the history records (§3.6 of docs/data-format.md): absolute rows, how each
        episode ended (TERMINATED, TRUNCATED, HISTORY_END) and the observation after its last step; None
        for a file that records none (older collections, the published dataset)."""
        groups = [self._file[span.name] for span in self.layout.groups]
        if not all(isinstance(g.get(FINAL_OBSERVATION), h5py.Dataset) for g in groups):
            return None
        with translate_hdf5_errors(self.path):
            rows = [span.start + g[EPISODE_END_ROW][()] for span, g in zip(self.layout.groups, groups, strict=True)]
            kinds = [g[EPISODE_END_KIND][()] for g in groups]
            final = [g[FINAL_OBSERVATION][()] for g in groups]
        return np.concatenate(rows).astype(np.int64), np.concatenate(kinds), np.concatenate(final)

    def read(self, start: int, stop: int, demonstrator_action: bool = False) -> dict[str, np.ndarray]:
        """Rows [start, stop) as ``observation``, ``action``, ``reward``, ``step_num`` in official dtypes,
        plus ``demonstrator_action`` if asked (a file without it raises)."""
        groups = self.layout.groups
        if not 0 <= start <= stop <= self.num_steps:
            raise IndexError(f"{self.path}: rows [{start}, {stop}) are outside [0, {self.num_steps})")
        fields = dict(FIELDS)
        if demonstrator_action:
            if self.layout.demonstrator_action is None:
                raise DatasetError(self.path, "stores no demonstrator actions (none of the datasets "
                                   f"{list(DEMONSTRATOR_ACTION_SPELLINGS)}); re-collect with `vintix collect`, "
                                   "which stores them")
            fields[DEMONSTRATOR_ACTION] = self.layout.demonstrator_action
        first = bisect_right([g.start for g in groups], start) - 1
        # An empty range still reads a 0-row slice of one group so the result has the right shapes.
        spans = list(takewhile(lambda g: g.start < stop, groups[first + 1 :]))
        spans.insert(0, groups[first])
        parts: dict[str, list[np.ndarray]] = {key: [] for key in fields}
        with translate_hdf5_errors(self.path):
            for g in spans:
                lo, hi = max(start, g.start) - g.start, min(stop, g.stop) - g.start
                group = self._file[g.name]
                for key, disk in fields.items():
                    if group[disk].dtype.kind not in NUMERIC_KINDS:  # bytes or strings would be parsed, or crash
                        raise DatasetError(self.path, f"{disk} in group {g.name!r} is stored as {group[disk].dtype}, "
                                           "not as numbers; run `vintix data validate` and re-collect the history")
                    parts[key].append(group[disk][lo:hi])
        # Cast so callers always get the official dtypes, even from a file that validation would flag.
        return {key: np.concatenate(parts[key]).astype(official_dtype(disk, self.layout.discrete), copy=False)
                for key, disk in fields.items()}

    def close(self) -> None:
        """Close the handle now (it would re-open on next use)."""
        if self._handle is not None and self._pid == os.getpid():
            self._handle.close()
        self._handle = None

    def __enter__(self) -> LearningHistory:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_handle": None, "_pid": None}

    def __repr__(self) -> str:
        return f"LearningHistory({str(self.path)!r})"


# --------------------------------------------------------------------------------------------
# Task metadata and discovery


_REQUIRED_KEYS = ("task_name", "observation_shape", "action_dim", "action_type")


def task_directory(root: PathLike, domain: str, task_dir_name: str) -> Path:
    """``<root>/<domain>/<task_dir_name>``: where a task's JSON and histories live."""
    return Path(root) / domain / task_dir_name


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
    """Load and check the task JSON; see `metadata_dims` for the dims it declares."""
    path = metadata_path(task_dir)
    fix = "fix it or rewrite it with vintix.data.write_task_metadata()"
    if not path.is_file():
        raise DatasetError(
            path, f"missing task metadata (keys {list(_REQUIRED_KEYS)}); write it with write_task_metadata()"
        )
    try:
        meta = json_loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise DatasetError(path, f"not valid JSON ({err}); {fix}") from err
    if not isinstance(meta, dict) or any(key not in meta for key in _REQUIRED_KEYS):
        raise DatasetError(path, f"needs keys {list(_REQUIRED_KEYS)}; {fix}")
    proprio = meta["observation_shape"].get("proprio") if isinstance(meta["observation_shape"], dict) else None
    checks = {
        "task_name must be a non-empty string": isinstance(meta["task_name"], str) and meta["task_name"],
        "observation_shape must be {'proprio': [obs_dim]}": (
            isinstance(proprio, list) and len(proprio) == 1 and _is_dim(proprio[0])
        ),
        "action_dim must be a positive integer": _is_dim(meta["action_dim"]),
        "action_type must be 'continuous' (or 'discrete', vintix's extension)": meta["action_type"] in ACTION_TYPES,
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


def _is_dim(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value > 0


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


def history_paths(task_dir: PathLike) -> list[Path]:
    """The task's finished histories, sorted (``*.h5.partial`` files are unfinished and never match)."""
    return sorted(p for p in Path(task_dir).glob("*.h5") if p.is_file())


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
