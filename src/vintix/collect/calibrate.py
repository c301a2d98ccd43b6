"""Fit each task's noise schedule to its own histories: spend the history where return changes with ε.

A power-law schedule moves ε at the same pace everywhere, so a task whose return changes only over a
narrow range of ε (a pendulum balances or falls) jumps there however the curvature is set. Histories
collected by `vintix collect` record their schedule, so every episode can be paired with the mean ε
it was played at; `fit_knots` turns those pairs into knots whose expected return rises linearly
along the history. `vintix data fit-schedule ROOT` prints them as recipe lines.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vintix.collect.noise import NoiseSchedule, fit_knots
from vintix.data.discovery import find_tasks
from vintix.data.layout import PathLike
from vintix.data.reader import LearningHistory
from vintix.errors import DatasetError


@dataclass(frozen=True)
class FittedSchedule:
    """The knots fitted for one task, and how many episodes they rest on."""

    task: str
    episodes: int
    knots: tuple[float, ...]


def complete_episodes(epsilon: np.ndarray, starts: np.ndarray, returns: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean ε, return and length of each episode of a run of ``len(epsilon)`` steps whose episodes begin
    at rows `starts` and earn `returns`, but the last (cut by the run's end)."""
    lengths = np.diff(np.append(starts, len(epsilon)))
    mean_epsilon = np.add.reduceat(epsilon, starts) / lengths
    return mean_epsilon[:-1], np.asarray(returns)[:-1], lengths[:-1]


def episode_noise(history: LearningHistory) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean ε, return and length of each episode of a history, but the last (cut by the history's end)."""
    attrs = history.attrs
    if "curvature" not in attrs or "steps" not in attrs:
        raise DatasetError(history.path, "records no noise schedule (it was not made by `vintix collect`), so the "
                                         "noise its episodes were played at is unknown")
    epsilon = NoiseSchedule.from_recorded(attrs).epsilon(np.arange(history.num_steps), int(attrs["steps"]))
    return complete_episodes(epsilon, history.episode_starts, history.episode_returns())


def pilot_knots(epsilon: np.ndarray, reward: np.ndarray, step_num: np.ndarray) -> tuple[float, ...]:
    """Knots for one history from its pilot run (ε, reward and step number per step, starting an episode):
    `fit_knots` on its complete episodes; linear decay, (1, 0), when its return does not fall with noise
    (a goal the demonstrator fails even noise-free). A pilot too short for two episodes is an error."""
    starts = np.flatnonzero(step_num == 0)
    returns = np.add.reduceat(reward.astype(np.float64), starts)
    episodes = complete_episodes(epsilon, starts, returns)
    if len(episodes[1]) < 2:
        raise ValueError(f"a pilot of {len(epsilon):,} steps completed {len(episodes[1])} episode(s), too few to fit "
                         "knots to: give pilot_steps worth many episodes (the paper recipe gives Meta-World 30,000)")
    try:
        return fit_knots(*episodes)
    except ValueError:
        return (1.0, 0.0)


def noise_free_return(history: LearningHistory) -> float:
    """Mean return of a history's noise-free episodes (ε = 0 throughout): its demonstrator's level on the
    very variant of the task it plays (a Meta-World history plays one hidden goal, whose demonstrator
    return can be a quarter or four times the task's mean over goals)."""
    epsilon, returns, _ = episode_noise(history)
    if not np.any(epsilon == 0):
        raise DatasetError(history.path, "has no complete noise-free episode to take its demonstrator's level "
                                         "from: collect with a noise-free fraction (f) that holds two episodes "
                                         "or more, or normalize by a reference table")
    return float(returns[epsilon == 0].mean())


def fit_schedules(root: PathLike, count: int = 11) -> tuple[list[FittedSchedule], list[str]]:
    """Knots for every task of a dataset, from all its histories together, and why any task has none."""
    fitted, skipped = [], []
    for task in find_tasks(root):
        parts = []
        for path in task.history_paths:
            with LearningHistory(path) as history:
                parts.append(episode_noise(history))
        epsilons, returns, lengths = ((np.concatenate(column) for column in zip(*parts, strict=True)) if parts
                                      else [np.empty(0)] * 3)
        try:
            fitted.append(FittedSchedule(task.task_name, len(returns), fit_knots(epsilons, returns, lengths, count)))
        except ValueError as error:
            skipped.append(f"{task.task_name}: {error}")
    return fitted, skipped
