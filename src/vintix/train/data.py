"""Training windows over learning histories: what the trainer feeds the model.

A *window* is ``L`` consecutive steps of one history after episode sparsity (keep every k-th
episode). Tasks are drawn uniformly (the paper) or by data volume; within a task every valid window
start is equally likely. Window ``i`` is a pure function of ``(seed, i)``, so the loader needs no
state of its own: a resumed run asks for the same indices and gets the same windows, forked
``DataLoader`` workers need no coordination, and DDP ranks simply take disjoint indices.

Per-task observation statistics are computed once by streaming over the HDF5 step groups (memory
stays at one group of rows) and cached under the dataset's fingerprint (file names, sizes, times, inodes),
so a changed history invalidates them. Before a task's statistics are first computed, its histories
pass the same checks as ``vintix data validate`` (finite values, step numbers, dtypes, dims, block
checksums): training never accepts a file that validation rejects, and one NaN can no longer turn a
task's observation mean, then the whole model, into NaN.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import torch

from vintix.atomic import atomic_write_text, file_name
from vintix.data.discovery import TaskData, find_tasks
from vintix.data.layout import dims_text
from vintix.data.reader import LearningHistory
from vintix.data.validate import task_mismatch, validate_history
from vintix.errors import DatasetError, UnknownTaskError, VintixError, json_loads
from vintix.model.model import GroupSpec, TaskNorm, episode_returns_so_far
from vintix.tasks import TaskSpec, get_task, resolve_tasks
from vintix.userdirs import user_cache_dir

TaskSampling = Literal["uniform", "volume"]
Window = dict[str, np.ndarray | int | str]
Batch = dict[str, dict[str, torch.Tensor]]
"""A micro-batch: group name -> that group's windows stacked (``task_idx``, ``obs``, ``prev_action``,
``prev_reward``, ``step_num``, ``action``, and ``prev_return`` where the dataset gives episode returns)."""


class TrainingDataError(VintixError, ValueError):
    """A dataset the trainer cannot use as it is (the message names the task and the fix)."""


# ----------------------------------------------------------------------------------------------
# Normalization statistics


def default_stats_cache_dir() -> Path:
    """``~/.cache/vintix/norm-stats``: outside the dataset, which may be read-only."""
    return user_cache_dir("norm-stats")


def _stats(paths: Sequence[Path]) -> list[tuple[Path, os.stat_result]]:
    """Each of `paths`, sorted, with its stat (one system call per file)."""
    return [(p, p.stat()) for p in sorted(paths)]


def content_fingerprint(paths: Sequence[Path]) -> list[list[str | int]]:
    """Name, size, mtime, inode and change time (ctime) of every history file: any rewritten or added history
    changes it, and so does an in-place change that keeps the size and restores the mtime (ctime is set by every
    write and no tool can set it back), while reading all the bytes of a large dataset to hash them is not paid.
    The one key of "this data" for the statistics cache and for resuming a run alike (a copy of the data is
    another key: its files are new inodes)."""
    return [[p.name, st.st_size, st.st_mtime_ns, st.st_ino, st.st_ctime_ns] for p, st in _stats(paths)]


def streaming_row_stats(histories: Sequence[LearningHistory]) -> tuple[np.ndarray, np.ndarray, int]:
    """Per-channel mean and std over every row, one HDF5 step group (<= 10k rows) at a time; the
    reward is the last channel, after the observation's.

    Chan et al.'s parallel merge of (count, mean, M2) in float64: exact up to rounding, and memory
    does not grow with the dataset.
    """
    count, mean, m2 = 0, None, None
    for history in histories:
        for span in history.layout.groups:
            rows = history.read(span.start, span.stop)
            obs = np.column_stack([rows["observation"], rows["reward"]]).astype(np.float64)
            n, chunk_mean = len(obs), obs.mean(axis=0)
            chunk_m2 = ((obs - chunk_mean) ** 2).sum(axis=0)
            if mean is None:
                count, mean, m2 = n, chunk_mean, chunk_m2
                continue
            delta = chunk_mean - mean
            total = count + n
            mean = mean + delta * n / total
            m2 = m2 + chunk_m2 + delta**2 * count * n / total
            count = total
    assert mean is not None and m2 is not None, "a task with histories has rows"
    return mean, np.sqrt(m2 / count), count


def check_histories(task: TaskData) -> None:
    """Refuse a task any of whose histories `vintix data validate` would flag (one full read)."""
    limit = _registry_spec(task).episode_limit
    problems = [f"{path.name}: {message}" for path in task.history_paths
                for message in validate_history(path, (task.obs_dim, task.act_dim), task.task_name, limit,
                                                task.discrete)]
    if problems:
        shown = "; ".join(problems[:3]) + (f"; and {len(problems) - 3} more" if len(problems) > 3 else "")
        raise TrainingDataError(
            f"{task.task_dir}: cannot train on task {task.task_name!r}: {shown}. Run `vintix data validate "
            f"{task.task_dir.parent.parent}` for every problem, then re-collect or remove the damaged files"
        )


def _finite(values: object) -> bool:
    return bool(np.isfinite(np.asarray(values, dtype=np.float64)).all())


def cached_obs_stats(task: TaskData, histories: Sequence[LearningHistory], cache_dir: Path
                     ) -> tuple[list[float], list[float], float]:
    """`streaming_row_stats` of a task (observation mean and std, reward std), read from / written to a
    per-task cache file keyed by `content_fingerprint`.

    A cache miss first validates the task's histories (`check_histories`); an entry is written only
    for histories that passed, and one without the ``validated`` mark (older vintix) or with
    non-finite statistics is recomputed, never trusted.
    """
    key = hashlib.sha1(str(task.task_dir.resolve()).encode()).hexdigest()[:16]
    path = cache_dir / f"{file_name(task.task_name)}-{key}.json"
    fingerprint = content_fingerprint(task.history_paths)
    if path.is_file():
        try:
            cached = json_loads(path.read_text())
            if (cached.get("fingerprint") == fingerprint and cached.get("validated") is True
                    and _finite(cached["obs_mean"]) and _finite(cached["obs_std"]) and _finite(cached["reward_std"])):
                return cached["obs_mean"], cached["obs_std"], cached["reward_std"]
        except (json.JSONDecodeError, KeyError, TypeError, ValueError):
            pass  # a damaged cache entry is recomputed, never trusted
    check_histories(task)
    mean, std, rows = streaming_row_stats(histories)
    if not (_finite(mean) and _finite(std)):  # validated rows are finite; this guards against overflow
        raise TrainingDataError(
            f"{task.task_dir}: the observation statistics of task {task.task_name!r} are not finite (mean {mean}, "
            f"std {std}): observations too large for float64 sums; check the data with `vintix data validate`"
        )
    entry = {"task_dir": str(task.task_dir.resolve()), "fingerprint": fingerprint, "rows": rows, "validated": True,
             "obs_mean": mean[:-1].tolist(), "obs_std": std[:-1].tolist(), "reward_std": float(std[-1])}
    atomic_write_text(path, json.dumps(entry) + "\n")
    return entry["obs_mean"], entry["obs_std"], entry["reward_std"]


# ----------------------------------------------------------------------------------------------
# Where windows may start


@dataclass
class HistoryWindows:
    """One history's usable episodes and, per sparsity k, how many windows start in each."""

    history: LearningHistory
    bounds: np.ndarray
    """Row where each usable episode starts, then the row where the last one ends."""
    _starts: dict[tuple[int, int], np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def steps(self) -> int:
        """Usable rows."""
        return int(self.bounds[-1] - self.bounds[0]) if len(self.bounds) else 0

    def starts_per_episode(self, window_len: int, sparsity: int) -> np.ndarray:
        """For each usable episode e, the number of offsets o such that episodes e, e+k, e+2k, ...
        from row ``bounds[e] + o`` on hold at least ``window_len`` rows."""
        key = (window_len, sparsity)
        if key not in self._starts:
            lengths = np.diff(self.bounds)
            # Rows in episodes e, e+k, e+2k, ... to the end: a reversed cumulative sum per residue class.
            kept = np.zeros_like(lengths)
            for r in range(sparsity):
                kept[r::sparsity] = np.cumsum(lengths[r::sparsity][::-1])[::-1]
            self._starts[key] = np.clip(kept - window_len + 1, 0, lengths)
        return self._starts[key]

    def segments(self, episode: int, offset: int, window_len: int, sparsity: int) -> list[tuple[int, int]]:
        """Row ranges [lo, hi) that make up the window starting ``offset`` rows into ``episode``."""
        segments, need, e = [], window_len, episode
        lo = int(self.bounds[e]) + offset
        while need:
            hi = min(int(self.bounds[e + 1]), lo + need)
            segments.append((lo, hi))
            need -= hi - lo
            e += sparsity
            if need:
                lo = int(self.bounds[e])
        return segments


def usable_bounds(history: LearningHistory, tail_fraction: float | None) -> np.ndarray:
    """Episode bounds of the whole history, or (expert distillation) of the episodes that start in
    its last ``tail_fraction`` of rows: the noise-free tail of paper Algorithm 1."""
    starts, n = history.episode_starts, history.num_steps
    if tail_fraction is not None:
        starts = starts[starts >= int(np.ceil((1.0 - tail_fraction) * n))]
    return np.append(starts, n).astype(np.int64) if len(starts) else np.zeros(0, np.int64)


# ----------------------------------------------------------------------------------------------
# The dataset as the trainer sees it


@dataclass
class TaskWindows:
    """One task: its group, its histories and its normalization."""

    name: str
    group: str
    norm: TaskNorm
    histories: list[HistoryWindows]
    fingerprint: list[list[str | int]]
    target: str = "action"
    """What the model learns to predict: the history's ``action``, or (expert distillation on every
    row) the ``demonstrator_action`` it stores."""

    @property
    def rows(self) -> str:
        """Which rows train it and on what target, in words (printed at the start of training)."""
        if self.target == "demonstrator_action":
            return "every row, target the demonstrator's action"
        whole = all(h.steps == h.history.num_steps for h in self.histories)
        return "every row, target the executed action" if whole else "noise-free tail, target the executed action"

    @property
    def steps(self) -> int:
        """Usable rows over all histories (the task's weight under volume sampling)."""
        return sum(h.steps for h in self.histories)


@dataclass
class TrainingData:
    """Tasks, groups and normalization of a dataset root, checked against the task registry."""

    root: Path
    tasks: list[TaskWindows]
    groups: list[GroupSpec]
    held_out: list[TaskNorm] = field(default_factory=list)
    """Statistics of the dataset's other tasks of the same groups, never trained on: a held-out task
    then reaches the model normalized like the tasks it was trained on."""

    @property
    def task_norms(self) -> list[TaskNorm]:
        """What `Vintix` takes as ``task_norms``: task index i = ``tasks[i]``, held-out tasks after them."""
        return [t.norm for t in self.tasks] + self.held_out

    @property
    def fingerprint(self) -> str:
        """One hash of every task's history files: stored in checkpoints to say what they were trained on."""
        text = json.dumps({t.name: t.fingerprint for t in self.tasks}, sort_keys=True)
        return hashlib.sha1(text.encode()).hexdigest()


def _learns_demonstrator_actions(histories: Sequence[LearningHistory], expert_distillation: bool,
                                 expert_rows: str) -> bool:
    """Expert distillation on every row: only where each history stores the demonstrator's actions."""
    return expert_distillation and expert_rows == "auto" and all(h.has_demonstrator_action for h in histories)


def _tail_fraction(task: TaskData, expert_distillation: bool, expert_tail_fraction: float | None) -> float | None:
    if not expert_distillation:
        return None
    fraction = expert_tail_fraction if expert_tail_fraction is not None else task.metadata.get("noise_free_fraction")
    if fraction is None:
        raise TrainingDataError(
            f"{task.task_dir}: expert distillation needs the noise-free tail fraction, but the task JSON has no "
            "'noise_free_fraction'; set expert_tail_fraction in the training config"
        )
    if not 0 < float(fraction) <= 1:
        raise TrainingDataError(f"{task.task_name}: noise-free tail fraction must lie in (0, 1], got {fraction}")
    return float(fraction)


def _registry_groups(specs: Sequence[TaskSpec]) -> list[GroupSpec]:
    """One GroupSpec per group, with the registry's dims (each task's data was checked against them)."""
    return [GroupSpec(spec.group, spec.obs_dim, spec.act_dim, spec.discrete)
            for spec in sorted({s.group: s for s in specs}.values(), key=lambda s: s.group)]


def _histories(task: TaskData) -> list[LearningHistory]:
    histories = [LearningHistory(p) for p in task.history_paths]
    for h in histories:
        if mismatch := task_mismatch(h.attrs.get("task"), task.task_name):
            raise DatasetError(h.path, f"{mismatch}; run `vintix data validate`")
        if mismatch := h.layout.mismatch(task.obs_dim, task.act_dim, task.discrete):
            raise DatasetError(h.path, f"{mismatch}; run `vintix data validate`")
    return histories


def load_training_data(
    root: str | os.PathLike[str],
    tasks: Sequence[str] = ("train",),
    expert_distillation: bool = False,
    expert_tail_fraction: float | None = None,
    stats_cache_dir: str | os.PathLike[str] | None = None,
    expert_rows: str = "auto",
    normalize_rewards: bool = False,
) -> TrainingData:
    """Index a dataset root for training: registry groups, reward scales, cached obs statistics.

    ``tasks`` selects the tasks trained on (`resolve_tasks` names, domains or splits; default the
    train split; empty = every task with histories). The dataset's other registry tasks in the same
    groups get observation statistics only (`TrainingData.held_out`). The reward scale is the task
    JSON's ``reward_scale`` when it has one (the data says how it was recorded), else the registry's;
    the group always comes from the registry; with ``normalize_rewards`` it is instead 1 / the std of
    the task's rewards in the data, so every task's rewards reach the model at unit scale. Expert
    distillation (see `TrainConfig.expert_rows`) learns the stored demonstrator actions on every row of
    a task whose histories all have them, else the executed actions of the noise-free tail.
    """
    root = Path(root)
    # Every folder must be a registry task, or its split (train or held out) would be a guess.
    found = [(t, _registry_spec(t)) for t in find_tasks(root) if t.history_paths]
    wanted = {spec.name for spec in resolve_tasks(list(tasks))} if tasks else None
    specs = [(task, spec) for task, spec in found if wanted is None or spec.name in wanted]
    if not specs:
        among = f" among {list(tasks)}" if tasks else ""
        raise TrainingDataError(f"{root}: no task folder with .h5 histories{among}; "
                                "collect data first (`vintix collect`) or check --data and the `tasks` setting")
    trained_groups = {spec.group for _, spec in specs}
    held_out = [(task, spec) for task, spec in found if (task, spec) not in specs and spec.group in trained_groups]
    groups = _registry_groups([spec for _, spec in specs + held_out])
    cache_dir = Path(stats_cache_dir) if stats_cache_dir is not None else default_stats_cache_dir()
    windows = []
    for task, spec in specs:
        histories = _histories(task)
        relabel = _learns_demonstrator_actions(histories, expert_distillation, expert_rows)
        tail = None if relabel else _tail_fraction(task, expert_distillation, expert_tail_fraction)
        norm = _task_norm(task, spec, histories, cache_dir, normalize_rewards)
        windows.append(TaskWindows(spec.name, spec.group, norm,
                                   [HistoryWindows(h, usable_bounds(h, tail)) for h in histories],
                                   content_fingerprint(task.history_paths),
                                   "demonstrator_action" if relabel else "action"))
    held_out_norms = [_task_norm(task, spec, _histories(task), cache_dir, normalize_rewards) for task, spec in held_out]
    names = [n.task for n in [w.norm for w in windows] + held_out_norms]
    if len(set(names)) != len(names):
        raise TrainingDataError(
            f"{root}: several task folders hold the same registry task ({sorted(names)}); merge them")
    return TrainingData(root, windows, groups, held_out_norms)


def _task_norm(task: TaskData, spec: TaskSpec, histories: Sequence[LearningHistory], cache_dir: Path,
               normalize_rewards: bool) -> TaskNorm:
    mean, std, reward_std = cached_obs_stats(task, histories, cache_dir)
    scale = float(task.metadata.get("reward_scale", spec.reward_scale))
    if normalize_rewards:
        scale = 1.0 / max(reward_std, 1e-8)  # a task whose reward never changes keeps it near 0 either way
    return TaskNorm(spec.name, spec.group, mean, std, scale)


def _registry_spec(task: TaskData) -> TaskSpec:
    """The registry's task for a dataset folder, which must hold data of the registry's dims: a group's
    tasks share encoders and a head, so a folder of another env version would train a wrong group."""
    try:
        spec = get_task(task.task_name)
    except UnknownTaskError as error:
        raise TrainingDataError(
            f"{task.task_dir}: task {task.task_name!r} is not in the task registry, so its group and reward scale are "
            f"unknown ({error}); rename task_name in its JSON to a registry name or leave the folder out"
        ) from error
    if (task.obs_dim, task.act_dim, task.discrete) != (spec.obs_dim, spec.act_dim, spec.discrete):
        raise TrainingDataError(
            f"{task.task_dir}: task {task.task_name!r} declares {dims_text(task.obs_dim, task.act_dim, task.discrete)} "
            f"but the task registry's {spec.name} (group {spec.group!r}) has "
            f"{dims_text(spec.obs_dim, spec.act_dim, spec.discrete, named=False)}; the "
            "folder holds another env version's or another task's data (MuJoCo -v4 and -v5 dims differ). Fix its "
            "JSON and histories or leave the folder out; `vintix data validate` flags it too"
        )
    return spec


# ----------------------------------------------------------------------------------------------
# Windows as a map-style dataset over an unbounded index


class WindowDataset(torch.utils.data.Dataset):
    """``dataset[i]``: window i, a deterministic function of ``(seed, i)``.

    The first token of a window that starts mid-episode carries the true previous action and
    reward (row ``start - 1``), not the episode-start padding. That is what the model sees at
    inference once its sliding window is full: the oldest cached token was embedded with its real
    previous action. Marking it as an episode start instead would teach the padding vectors to
    appear mid-episode and contradict ``step_num``.
    """

    def __init__(self, data: TrainingData, window_len: int, sparsity: int = 1, stochastic_sparsity: bool = False,
                 task_sampling: TaskSampling = "uniform", seed: int = 0, episode_returns: bool = False) -> None:
        """`episode_returns`: also give each window ``prev_return``, what each token's episode earned before it
        (`vintix.model.ModelConfig.episode_return`)."""
        if window_len < 1 or sparsity < 1:
            raise ValueError(f"window_len and episode sparsity must be >= 1, got {window_len} and {sparsity}")
        if task_sampling not in ("uniform", "volume"):
            raise ValueError(f"task_sampling must be 'uniform' or 'volume', got {task_sampling!r}")
        self.data, self.window_len, self.seed, self.episode_returns = data, window_len, seed, episode_returns
        self.sparsities = list(range(1, sparsity + 1)) if stochastic_sparsity else [sparsity]
        self._check_windows_fit()
        weights = np.array([t.steps if task_sampling == "volume" else 1.0 for t in data.tasks], dtype=np.float64)
        self.task_probs = weights / weights.sum()

    def _check_windows_fit(self) -> None:
        too_short = []
        for task in self.data.tasks:
            for k in self.sparsities:
                if not any(h.starts_per_episode(self.window_len, k).sum() for h in task.histories):
                    longest = max(h.steps for h in task.histories)
                    too_short.append(f"{task.name} (longest usable history {longest} steps, sparsity {k})")
                    break
        if too_short:
            raise TrainingDataError(
                f"no history holds a window of {self.window_len} steps for: {'; '.join(too_short)}. Use a shorter "
                "window_len, a lower episode_sparsity, longer histories, or leave these tasks out"
            )

    def locate(self, index: int) -> tuple[int, int, int, int, int]:
        """(task, history, episode, offset, sparsity) of window ``index``."""
        rng = np.random.default_rng((self.seed, index))
        t = int(rng.choice(len(self.data.tasks), p=self.task_probs))
        k = self.sparsities[int(rng.integers(len(self.sparsities)))]
        task = self.data.tasks[t]
        per_history = [h.starts_per_episode(self.window_len, k) for h in task.histories]
        totals = np.array([s.sum() for s in per_history], dtype=np.float64)
        h = int(rng.choice(len(totals), p=totals / totals.sum()))
        # One uniform draw over every valid (episode, offset) pair of the history.
        flat = int(rng.integers(totals[h]))
        cumulative = np.cumsum(per_history[h])
        e = int(np.searchsorted(cumulative, flat, side="right"))
        offset = flat - (int(cumulative[e - 1]) if e else 0)
        return t, h, e, offset, k

    def __getitem__(self, index: int) -> Window:
        t, h, e, offset, k = self.locate(index)
        task = self.data.tasks[t]
        history = task.histories[h]
        parts: dict[str, list[np.ndarray]] = {key: [] for key in ("obs", "step_num", "action")}
        executed: dict[str, list[np.ndarray]] = {"action": [], "reward": []}
        before: dict[str, np.ndarray] = {}
        earned = 0.0  # by the window's first row, in its episode
        for n, (lo, hi) in enumerate(history.segments(e, offset, self.window_len, k)):
            # The window's first token reads the history's previous row, if any, for its previous action and
            # reward: a mid-episode one is what the model sees once its sliding window is full, and an
            # episode start's reward is the previous episode's last (`ModelConfig.last_reward`). One that opens
            # mid-episode reads from its episode's start for what the episode earned before it.
            first = lo - 1 if n == 0 and lo > 0 else lo
            if n == 0 and offset and self.episode_returns:
                first = int(history.bounds[e])
            rows = history.history.read(first, hi, demonstrator_action=task.target == "demonstrator_action")
            check_finite_rows(history.history.path, first, rows)
            skip = lo - first
            if skip:
                before = {key: rows[key][skip - 1] for key in executed}
                earned = float(rows["reward"][:skip].sum()) if offset else 0.0
            for key in executed:
                executed[key].append(rows[key][skip:])
            parts["obs"].append(rows["observation"][skip:])
            parts["step_num"].append(rows["step_num"][skip:].astype(np.int64))
            # The context always holds the actions that were executed; the target may be the demonstrator's.
            parts["action"].append(rows[task.target][skip:])
        window: Window = {key: np.concatenate(value) for key, value in parts.items()}
        # Token t carries step t-1's action and reward, across segment borders too: with episode sparsity an
        # episode's start carries the last reward of the episode before it in the window. The history's
        # first row has none (zeros).
        previous = {}
        for key, name in (("action", "prev_action"), ("reward", "prev_reward")):
            done = np.concatenate(executed[key])
            first_row = before.get(key, np.zeros_like(done[0]))
            previous[name] = window[name] = np.concatenate([first_row[None], done[:-1]])
        if self.episode_returns:
            starts = np.concatenate(parts["step_num"]) == 0
            window["prev_return"] = episode_returns_so_far(previous["prev_reward"][None], starts[None],
                                                           np.array([earned]))[0]
        window.update(task_idx=t, group=task.group)
        return window


def check_finite_rows(path: Path, first: int, rows: dict[str, np.ndarray]) -> None:
    """DatasetError naming `path` where rows read from it (starting at row `first`) hold NaN or inf: a file
    changed while training reads it (after validation), which would otherwise end as a NaN loss."""
    for name, values in rows.items():
        if np.issubdtype(values.dtype, np.floating) and not np.isfinite(values).all():
            row = first + int(np.flatnonzero(~np.isfinite(values.reshape(len(values), -1)).all(axis=1))[0])
            raise DatasetError(path, f"{name} at row {row} is NaN or inf; the file changed after it was validated: "
                                     "run `vintix data validate` on the dataset, and re-collect or remove the history")


def collate_windows(windows: Sequence[Window]) -> Batch:
    """Stack windows per group (sorted by group name, so every rank and run sees the same order)."""
    by_group: dict[str, list[Window]] = {}
    for w in windows:
        by_group.setdefault(str(w["group"]), []).append(w)
    batch: Batch = {}
    for group in sorted(by_group):
        members = by_group[group]
        stacked: dict[str, torch.Tensor] = {key: torch.from_numpy(np.stack([w[key] for w in members]))
                   for key in ("obs", "prev_action", "prev_reward", "prev_return", "step_num", "action")
                   if key in members[0]}
        stacked["task_idx"] = torch.tensor([int(w["task_idx"]) for w in members], dtype=torch.long)
        batch[group] = stacked
    return batch


class WindowBatches(torch.utils.data.Sampler[list[int]]):
    """Unbounded micro-batches of window indices for one rank, from a given micro-batch on.

    Micro-batch m of rank r holds indices ``(m * world + r) * batch_size + j``: ranks never share a
    window, and resuming at micro-batch m replays exactly what an uninterrupted run would see.
    """

    def __init__(self, batch_size: int, start_micro_batch: int = 0, rank: int = 0, world_size: int = 1) -> None:
        self.batch_size, self.start, self.rank, self.world = batch_size, start_micro_batch, rank, world_size

    def __iter__(self) -> Iterator[list[int]]:
        m = self.start
        while True:
            first = (m * self.world + self.rank) * self.batch_size
            yield list(range(first, first + self.batch_size))
            m += 1
