"""``vintix bench collect``: the collector's steps/s against the raw simulator's, on the same work.

The collector rate is `collect_batch` in one process: demonstrator, noise, bookkeeping and writing
the HDF5 files included. The raw rate is the env alone replaying what was collected: each history's
actions fed to a fresh env of the same seed, reset where the history starts its episodes, nothing
else. Both make the same envs and do the same steps and resets (random play ends Hopper episodes
every ~20 steps, a demonstrator's last 1,000, so a random-action rate would measure another workload). Their
ratio is the share of the simulator's speed the collector keeps. Collecting and replaying alternate
`repeats` times and each keeps its median, so a load that comes and goes touches both alike.
"""

from __future__ import annotations

import csv
import datetime
import io
import statistics
import tempfile
import time
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from tqdm import tqdm

from vintix.atomic import atomic_write_text
from vintix.collect.collector import CollectionPlan, collect_batch
from vintix.data import LearningHistory
from vintix.demonstrators import Demonstrator, load_demonstrator
from vintix.errors import VintixError
from vintix.tasks import get_task, make_env
from vintix.tasks.check import random_policy_returns

RATES_FIELDS = ["task", "envs_per_batch", "raw_steps_per_s", "collect_steps_per_s", "measured_on", "command"]


@dataclass(frozen=True)
class CollectBenchmark:
    """One task's measured collection and raw env speed."""

    task: str
    envs_per_batch: int
    raw_steps_per_s: float
    collect_steps_per_s: float | None
    """None for a task without a demonstrator: its raw rate is then uniform-random play's."""

    @property
    def ratio(self) -> float | None:
        """Collector speed as a fraction of the raw env speed."""
        return None if self.collect_steps_per_s is None else self.collect_steps_per_s / self.raw_steps_per_s


def rates_path() -> Path:
    """The package's table of measured collection rates (what `vintix collect --plan` estimates from)."""
    return Path(str(resources.files("vintix.collect").joinpath("rates.csv")))


def write_rates(results: list[CollectBenchmark], path: Path, command: str) -> Path:
    """Add the benchmark's results to the rates table at `path` (created if missing), atomically: a task
    measured again gets its new row in place of the old one, the other tasks' rows stay as they were."""
    rows: dict[str, dict[str, str]] = {}
    if path.is_file():
        read_rates(path)  # a file that is not a rates table is an error, never overwritten
        with open(path, newline="") as file:
            rows = {row["task"]: row for row in csv.DictReader(file)}
    today = datetime.date.today().isoformat()
    for r in results:
        collected = "" if r.collect_steps_per_s is None else str(round(r.collect_steps_per_s))
        rows[r.task] = {"task": r.task, "envs_per_batch": str(r.envs_per_batch),
                        "raw_steps_per_s": str(round(r.raw_steps_per_s)), "collect_steps_per_s": collected,
                        "measured_on": today, "command": command}
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=RATES_FIELDS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows.values())
    atomic_write_text(path, buffer.getvalue())
    return path


def read_rates(path: Path | None = None) -> dict[str, CollectBenchmark]:
    """Task -> measured rates, from `path` (default: the package's table)."""
    path = path or rates_path()
    try:
        with open(path, newline="") as file:
            rates = {row["task"]: CollectBenchmark(
                         row["task"], int(row["envs_per_batch"]), float(row["raw_steps_per_s"]),
                         float(row["collect_steps_per_s"]) if row["collect_steps_per_s"] else None)
                     for row in csv.DictReader(file)}
    except (OSError, UnicodeDecodeError, KeyError, TypeError, ValueError) as error:
        raise VintixError(f"{path}: not a readable rates table ({type(error).__name__}: {error}); it needs the columns "
                          f"{RATES_FIELDS[:4]}: write one with `vintix bench collect TASKS --out {path}`") from error
    # A rate of 0, NaN or below would turn an estimate into a division by zero, NaN hours or negative ones.
    bad = [f"{r.task}: {value}" for r in rates.values()
           for value in (r.raw_steps_per_s, r.collect_steps_per_s) if value is not None and not value > 0]
    if bad or any(r.envs_per_batch < 1 for r in rates.values()):
        raise VintixError(f"{path}: rates must be positive numbers of steps per second and envs_per_batch >= 1, got "
                          f"{'; '.join(bad) or 'envs_per_batch < 1'}; measure them again with `vintix bench collect "
                          f"TASKS --out {path}`")
    return rates


def replay_seconds(task: str, history: Path) -> float:
    """Seconds the env alone takes to replay a history: made with its env seed (making it is timed, as
    the collector's is), then its actions, reset where its episodes start."""
    with LearningHistory(history) as stored:
        rows, env_seed = stored.read(0, stored.num_steps), stored.env_seed
    ends = np.append(rows["step_num"][1:] == 0, False)  # reset after the last step of each episode
    start = time.perf_counter()
    env = make_env(task, seed=env_seed)
    env.reset()
    for action, end in zip(rows["action"], ends, strict=True):
        env.step(action)
        if end:
            env.reset()
    seconds = time.perf_counter() - start
    env.close()
    return seconds


def measure_once(task: str, steps: int, envs_per_batch: int, demonstrator: Demonstrator) -> tuple[float, float]:
    """(raw, collector) steps/s of one `collect_batch` of `envs_per_batch` histories and its replay
    (the demonstrator is loaded by the caller, outside the timing, as a long collection loads it once)."""
    plan = CollectionPlan(task, histories=envs_per_batch, steps=max(1, steps // envs_per_batch),
                          envs_per_batch=envs_per_batch)
    with tempfile.TemporaryDirectory() as root:
        start = time.perf_counter()
        paths = collect_batch(plan, list(range(envs_per_batch)), Path(root), demonstrator)
        collecting = time.perf_counter() - start
        replaying = sum(replay_seconds(task, path) for path in paths)
    total = plan.steps * envs_per_batch
    return total / replaying, total / collecting


def demonstrator_or_none(task: str) -> Demonstrator | None:
    try:
        return load_demonstrator(task)
    except VintixError:
        return None


def benchmark_collection(tasks: list[str], steps: int, envs_per_batch: int, repeats: int = 3) -> list[CollectBenchmark]:
    """Raw and collector steps/s of each task, `repeats` times, medians kept; tasks without a
    demonstrator get uniform-random play's rate only."""
    results = []
    for task in tqdm(tasks, desc="tasks", disable=True if len(tasks) < 2 else None):
        spec = get_task(task)
        name, demonstrator = spec.name, demonstrator_or_none(spec.name)
        if demonstrator is None:  # uniform-random play over about `steps` steps, as `vintix check-envs` times it
            episodes = max(1, steps // spec.episode_length)
            raw = [random_policy_returns(name, episodes).steps_per_second for _ in range(repeats)]
            results.append(CollectBenchmark(name, envs_per_batch, statistics.median(raw), None))
            continue
        rates = [measure_once(name, steps, envs_per_batch, demonstrator) for _ in range(repeats)]
        results.append(CollectBenchmark(name, envs_per_batch, statistics.median(r for r, _ in rates),
                                        statistics.median(c for _, c in rates)))
    return results
