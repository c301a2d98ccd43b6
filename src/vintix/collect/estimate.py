"""What a collection would produce and cost, before it runs (``vintix collect --plan``).

Steps and histories come from the plans. Disk size follows from the format: every row stores the
observation, the action, the demonstrator's action, the reward and the step number (4 bytes each),
in checksummed chunks of up to `CHECKSUM_CHUNK_ROWS` rows allocated whole, plus about 16 kB of HDF5
metadata per step group. Time comes from the measured rates table (`vintix bench collect --out`):
each batch takes its steps (and its pilots') over the task's collector rate, and batches go to `workers` processes
in the order `collect` submits them, each taken by the first worker free. A task without a
measured collector rate (no demonstrator yet) is estimated from its raw env rate and the median
collector/raw ratio of the tasks that have one, and marked as such.
"""

from __future__ import annotations

import heapq
import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

from vintix.collect.bench import CollectBenchmark
from vintix.collect.collector import CollectionPlan, batches
from vintix.data.hdf5 import CHECKSUM_CHUNK_ROWS, MAX_GROUP_ROWS
from vintix.errors import VintixError
from vintix.tasks import TaskSpec, get_task

GROUP_METADATA_BYTES = 24_000
"""HDF5 metadata per step group (measured on our files: size minus allocated chunks; 7,900 of it for the
three episode-end datasets, docs/data-format.md §3.6)."""
ROOT_ATTRIBUTE_BYTES = 4_300
"""The root attributes that say how a history was made (task, seeds, schedule): they overflow the root
group's header into a block of their own (measured: files of 250 to 12,345 steps are 4,220-4,300 bytes
larger than their chunks and group metadata)."""


@dataclass(frozen=True)
class TaskEstimate:
    """What collecting one plan would produce and take."""

    task: str
    histories: int
    steps_per_history: int
    pilot_steps: int
    """Steps each history's pilot plays before it (not stored; 0: none)."""
    batches: list[int]
    """Histories in each batch."""
    bytes: int
    steps_per_s: float
    """Collector steps/s of one process on this task."""
    measured: bool
    """False: steps_per_s estimated from the raw env rate (no demonstrator to measure with)."""

    @property
    def steps(self) -> int:
        return self.histories * self.steps_per_history

    @property
    def batch_seconds(self) -> list[float]:
        return [n * (self.pilot_steps + self.steps_per_history) / self.steps_per_s for n in self.batches]


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


def collector_rate(task: str, rates: dict[str, CollectBenchmark]) -> tuple[float, bool]:
    """(collector steps/s, measured?) of a task from the rates table."""
    if task not in rates:
        raise VintixError(f"no measured rate for {task!r} in the rates table; measure it with "
                          f"`vintix bench collect {task} --out rates.csv` and pass --rates rates.csv")
    rate = rates[task]
    if rate.collect_steps_per_s is not None:
        return rate.collect_steps_per_s, True
    ratios = [r.ratio for r in rates.values() if r.ratio is not None]
    if not ratios:
        raise VintixError("the rates table has no task with a measured collector rate to estimate from")
    return rate.raw_steps_per_s * statistics.median(ratios), False


def estimate_plans(plans: Sequence[CollectionPlan], rates: dict[str, CollectBenchmark]) -> list[TaskEstimate]:
    """Steps, disk size and collector rate of each plan."""
    estimates = []
    for plan in plans:
        spec = get_task(plan.task)
        steps_per_s, measured = collector_rate(spec.name, rates)
        estimates.append(TaskEstimate(spec.name, plan.histories, plan.steps, plan.schedule.pilot_steps,
                                      [len(b) for b in batches(plan)],
                                      plan.histories * history_bytes(spec, plan.steps), steps_per_s, measured))
    return estimates


def wall_seconds(estimates: Sequence[TaskEstimate], workers: int) -> float:
    """When the last batch would finish with `workers` processes taking batches in submission order."""
    if workers < 1:
        raise VintixError(f"workers must be >= 1, got {workers}")
    free_at = [0.0] * workers
    for seconds in (s for e in estimates for s in e.batch_seconds):
        heapq.heappush(free_at, heapq.heappop(free_at) + seconds)
    return max(free_at)
