"""Writing one learning history file atomically, group by group (`LearningHistoryWriter`); the format:
`vintix.data.layout`, docs/data-format.md."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from vintix.atomic import make_parent_dirs, new_partial_file, os_error_in, publish
from vintix.data.layout import (
    CHECKSUM_CHUNK_ROWS,
    DEMONSTRATOR_ACTION,
    DTYPES,
    EPISODE_END_KIND,
    EPISODE_END_ROW,
    FIELDS,
    FINAL_OBSERVATION,
    HISTORY_END,
    MAX_GROUP_ROWS,
    TERMINATED,
    TRUNCATED,
    PathLike,
    is_action_dataset,
    is_dim,
    official_dtype,
    step_num_breaks,
)
from vintix.errors import DatasetError

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
        if not (is_dim(obs_dim) and is_dim(act_dim)):
            raise DatasetError(self.path,
                               f"obs_dim and act_dim must be positive integers, got {obs_dim!r} and {act_dim!r}")
        if not (is_dim(chunk_size) and chunk_size <= MAX_GROUP_ROWS):
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
