"""Learning histories in the official Vintix on-disk format (HDF5 + one JSON per task): the layout, its constants
and the checks of a file's groups, shared by the writer (`vintix.data.writer`), the reader (`vintix.data.reader`)
and discovery (`vintix.data.discovery`).

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

import math
import os
import re
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from vintix.errors import DatasetError
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


def is_dim(value: Any) -> bool:
    """Whether `value` can be a dimension: a positive int (a bool is not one)."""
    return isinstance(value, int) and not isinstance(value, bool) and value > 0

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
