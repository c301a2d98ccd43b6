"""Figure 3 of the paper for any dataset: how episode return rises along the learning histories.

Each history's episode returns are normalized by the task's reference scores,
`(R − random) / (expert − random)`, and spread over the steps of their episode; the curve is the mean
over each of `bins` equal fractions of the history's *steps*, so a bin always has a value however
long the episodes are (a 30k-step Swimmer history has only 30 episodes). A task's curve is the IQM
over its histories; a domain's is the IQM over all the histories of its tasks, so every history
weighs the same. The reference table is ours by default (our demonstrators' measured returns: the
paper's are from other env versions), or the paper's. With `history_expert`, each history's
demonstrator level is instead read from the history itself, e.g. from its own noise-free tail
(`vintix.collect.calibrate.noise_free_return`): the fair scale where histories of one task play
different variants (Meta-World's hidden goals), whose demonstrator returns differ several-fold.

The same curves give the smoothness criterion a noise schedule is chosen by (`smoothness`): a
history should rise steadily (rank correlation of return with position), without abrupt jumps
(largest change between neighbouring bins) and all the way (first bin to last), which the paper's
linear decay often fails.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure  # figures straight to files: no pyplot state, no GUI backend
from scipy.stats import spearmanr, trim_mean

from vintix.atomic import atomic_path, file_name
from vintix.data.discovery import find_tasks
from vintix.data.layout import PathLike
from vintix.data.reader import LearningHistory
from vintix.errors import UnknownTaskError, VintixError, printable
from vintix.tasks.scores import reference

SMOOTH_CORRELATION = 0.9
"""A smooth history's return rises with its position: Spearman correlation at least this, over the bins."""
SMOOTH_JUMP = 0.3
"""...no neighbouring bins differ by more than this much normalized return (an abrupt jump)..."""
SMOOTH_RISE = 0.6
"""...and it rises at least this much from its first bin to its last (from near random to near the
demonstrator: a schedule that drops the noise at once is steady but teaches no improvement)."""

HistoryExpert = Callable[[LearningHistory], float]
"""A history's own demonstrator level, read from the history (`vintix.collect.calibrate.noise_free_return`)."""


def normalized_curve(episode_returns: np.ndarray, episode_lengths: np.ndarray, random: float, expert: float,
                     bins: int) -> np.ndarray:
    """Mean normalized return over the steps in each of `bins` equal fractions of the history."""
    scores = (np.asarray(episode_returns, dtype=np.float64) - random) / (expert - random)
    per_step = np.repeat(scores, episode_lengths)
    which = np.arange(len(per_step)) * bins // len(per_step)
    with np.errstate(invalid="ignore"):  # NaN only where a history has fewer steps than bins
        return np.bincount(which, weights=per_step, minlength=bins) / np.bincount(which, minlength=bins)


def iqm(curves: np.ndarray) -> np.ndarray:
    """Interquartile mean over histories (rows), bin by bin."""
    return trim_mean(curves, 0.25, axis=0)


def _plot(curves: dict[str, np.ndarray], title: str, path: Path) -> Path:
    figure = Figure(figsize=(6, 4))
    axis = figure.subplots()
    bins = next(iter(curves.values())).shape[1]
    fraction = (np.arange(bins) + 0.5) / bins
    for label, task_curves in sorted(curves.items()):
        axis.plot(fraction, iqm(task_curves), label=f"{printable(label, breaks=False)} ({len(task_curves)} histories)")
    axis.axhline(1.0, color="gray", linestyle="--", linewidth=0.8)
    axis.axhline(0.0, color="gray", linestyle=":", linewidth=0.8)
    axis.set(xlabel="fraction of the learning history", ylabel="normalized episode return (IQM)",
             title=printable(title, breaks=False))
    axis.legend(fontsize=7)
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png", dpi=110, bbox_inches="tight")
    return path


def task_curves(root: PathLike, bins: int, reference_table: str = "ours",
                history_expert: HistoryExpert | None = None) -> tuple[dict[str, dict[str, np.ndarray]], list[str]]:
    """Domain -> task -> normalized curves of its histories ([histories, bins]), and the tasks skipped:
    unknown to the registry, or without a reference in `reference_table` ('ours' or 'paper').
    `history_expert`: each history's expert level is what it returns for the history (e.g. the mean
    return of its noise-free episodes) instead of the table's."""
    if bins < 1:
        raise VintixError(f"bins must be >= 1, got {bins}")
    by_domain: dict[str, dict[str, np.ndarray]] = defaultdict(dict)
    skipped = []
    for task in find_tasks(root):
        try:
            scores = reference(task.task_name, reference_table)
        except UnknownTaskError:
            scores = None
        if scores is None or not task.history_paths:
            skipped.append(task.task_name)
            continue
        curves = []
        for path in task.history_paths:
            with LearningHistory(path) as history:
                returns = history.episode_returns()
                lengths = history.episode_lengths()
                if len(returns) > 1:  # the history's end usually cuts its last episode short: a fake dip
                    returns, lengths = returns[:-1], lengths[:-1]
                expert = scores.expert if history_expert is None else history_expert(history)
                curves.append(normalized_curve(returns, lengths, scores.random, expert, bins))
        by_domain[task.domain][task.task_name] = np.array(curves)
    return by_domain, skipped


def plot_dataset(root: PathLike, out: PathLike, bins: int = 50, reference_table: str = "ours",
                 history_expert: HistoryExpert | None = None) -> tuple[list[Path], list[str]]:
    """One PNG per task and one per domain under `out`, normalized by `reference_table` ('ours' or
    'paper'; see `task_curves` for `history_expert`). Returns the figures and the tasks skipped."""
    by_domain, skipped = task_curves(root, bins, reference_table, history_expert)
    out = Path(out)
    written = []
    for domain, tasks in sorted(by_domain.items()):
        for name, curves in sorted(tasks.items()):
            # A task's name comes from its JSON: as a file name, never a path out of --out.
            written.append(_plot({name: curves}, name, out / file_name(domain) / f"{file_name(name)}.png"))
        written.append(_plot({domain: np.concatenate(list(tasks.values()))},
                             f"{domain}: {len(tasks)} tasks", out / f"{file_name(domain)}.png"))
    return written, skipped


@dataclass(frozen=True)
class Smoothness:
    """How smoothly one task's histories rise from random to demonstrator level (worst history shown)."""

    task: str
    histories: int
    rank_correlation: float
    """Lowest, over histories, Spearman correlation of the normalized return with the position in the
    history (1: it only ever rises)."""
    largest_jump: float
    """Largest change of normalized return between neighbouring bins of any history (a linear rise
    over 10 bins moves about 0.1 per bin)."""
    start: float
    """Mean normalized return of the first bin (random play: about 0)."""
    end: float
    """Mean normalized return of the last bin (the demonstrator: about 1)."""

    def smooth(self) -> bool:
        return (self.rank_correlation >= SMOOTH_CORRELATION and self.largest_jump <= SMOOTH_JUMP
                and self.end - self.start >= SMOOTH_RISE)


def smoothness(root: PathLike, bins: int = 10, reference_table: str = "ours",
               history_expert: HistoryExpert | None = None) -> tuple[list[Smoothness], list[str]]:
    """The smoothness criterion of every task of a dataset (see `Smoothness`; `history_expert`: see
    `task_curves`), and the tasks skipped."""
    by_domain, skipped = task_curves(root, bins, reference_table, history_expert)
    results = []
    for tasks in by_domain.values():
        for name, curves in sorted(tasks.items()):
            position = np.arange(bins)
            correlations = [spearmanr(position, curve).statistic for curve in curves]
            results.append(Smoothness(name, len(curves), float(np.nanmin(correlations)),
                                      float(np.nanmax(np.abs(np.diff(curves, axis=1)))),
                                      float(np.nanmean(curves[:, 0])), float(np.nanmean(curves[:, -1]))))
    return results, skipped
