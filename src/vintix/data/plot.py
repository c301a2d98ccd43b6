"""Figure 3 of the paper for any dataset: how episode return rises along the learning histories.

Each history's episode returns are normalized by the task's reference scores,
`(R − random) / (expert − random)`, placed at their fraction of the history, and averaged into
`bins` equal bins. A task's curve is the IQM over its histories; a domain's is the IQM over all the
histories of its tasks, so every history weighs the same.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure  # figures straight to files: no pyplot state, no GUI backend
from scipy.stats import trim_mean

from vintix.atomic import atomic_path
from vintix.data.hdf5 import LearningHistory, PathLike, find_tasks
from vintix.errors import UnknownTaskError
from vintix.tasks import get_task


def normalized_curve(episode_returns: np.ndarray, random: float, expert: float, bins: int) -> np.ndarray:
    """Mean normalized return in each of `bins` equal fractions of the history (NaN where no episode)."""
    scores = (np.asarray(episode_returns, dtype=np.float64) - random) / (expert - random)
    position = (np.arange(len(scores)) + 0.5) / len(scores)
    which = np.minimum((position * bins).astype(int), bins - 1)
    total = np.bincount(which, weights=scores, minlength=bins)
    count = np.bincount(which, minlength=bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        return total / count


def iqm(curves: np.ndarray) -> np.ndarray:
    """Interquartile mean over histories (rows), bin by bin."""
    return trim_mean(curves, 0.25, axis=0)


def _plot(curves: dict[str, np.ndarray], title: str, path: Path) -> Path:
    figure = Figure(figsize=(6, 4))
    axis = figure.subplots()
    bins = next(iter(curves.values())).shape[1]
    fraction = (np.arange(bins) + 0.5) / bins
    for label, task_curves in sorted(curves.items()):
        axis.plot(fraction, iqm(task_curves), label=f"{label} ({len(task_curves)} histories)")
    axis.axhline(1.0, color="gray", linestyle="--", linewidth=0.8)
    axis.axhline(0.0, color="gray", linestyle=":", linewidth=0.8)
    axis.set(xlabel="fraction of the learning history", ylabel="normalized episode return (IQM)", title=title)
    axis.legend(fontsize=7)
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png", dpi=110, bbox_inches="tight")
    return path


def plot_dataset(root: PathLike, out: PathLike, bins: int = 50) -> list[Path]:
    """One PNG per task and one per domain under `out`; normalized by the registry's (paper's) scores.
    Tasks the registry does not know are skipped (they have no reference scores)."""
    out = Path(out)
    by_domain: dict[str, dict[str, np.ndarray]] = defaultdict(dict)
    for task in find_tasks(root):
        try:
            spec = get_task(task.task_name)
        except UnknownTaskError:
            continue
        curves = []
        for path in task.history_paths:
            with LearningHistory(path) as history:
                curves.append(normalized_curve(history.episode_returns(), spec.paper_random.mean,
                                               spec.paper_expert.mean, bins))
        if curves:
            by_domain[task.domain][spec.name] = np.array(curves)
    written = []
    for domain, tasks in sorted(by_domain.items()):
        for name, curves in sorted(tasks.items()):
            written.append(_plot({name: curves}, name, out / domain / f"{name}.png"))
        written.append(_plot({domain: np.concatenate(list(tasks.values()))},
                             f"{domain}: {len(tasks)} tasks", out / f"{domain}.png"))
    return written
