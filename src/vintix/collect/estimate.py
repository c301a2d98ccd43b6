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
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

from vintix.collect.bench import CollectBenchmark
from vintix.collect.collector import CollectionPlan, batches
from vintix.data.layout import history_bytes
from vintix.errors import VintixError
from vintix.tasks import get_task


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
