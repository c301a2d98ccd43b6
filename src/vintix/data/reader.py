"""Reading one learning history file lazily and fork-safely (`LearningHistory`); the format: `vintix.data.layout`,
docs/data-format.md."""

from __future__ import annotations

import os
from bisect import bisect_right
from itertools import takewhile
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from vintix.data.layout import (
    DEMONSTRATOR_ACTION,
    DEMONSTRATOR_ACTION_SPELLINGS,
    EPISODE_END_KIND,
    EPISODE_END_ROW,
    FIELDS,
    FINAL_OBSERVATION,
    NUMERIC_KINDS,
    Layout,
    PathLike,
    inspect_layout,
    official_dtype,
    open_hdf5,
    translate_hdf5_errors,
)
from vintix.errors import DatasetError


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
