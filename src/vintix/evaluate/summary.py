"""Aggregates of normalized scores: IQM with bootstrap confidence intervals, best-k-shot plateau, and
the gap between two conditions' converged scores (e.g. true vs zero rewards fed back)."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.stats import bootstrap, trim_mean


def iqm(values: np.ndarray, axis: int = 0) -> np.ndarray:
    """Interquartile mean (the mean of the middle 50 %), robust to a few failed runs."""
    return trim_mean(values, 0.25, axis=axis)


def estimate_with_ci(values: np.ndarray, statistic: Callable[..., np.ndarray] = iqm, confidence: float = 0.95,
                     resamples: int = 2000, seed: int = 0) -> tuple[float, float, float]:
    """`statistic` (IQM, or np.mean) of 1-D `values` and its percentile-bootstrap confidence interval over the
    values. With fewer than 2 values there is nothing to resample: the interval is the point itself."""
    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    if len(values) == 0:
        return float("nan"), float("nan"), float("nan")
    point = float(statistic(values, axis=0))
    if len(values) < 2 or np.ptp(values) == 0:
        return point, point, point
    result = bootstrap((values,), statistic, confidence_level=confidence, n_resamples=resamples,
                       method="percentile", vectorized=True, axis=-1, random_state=np.random.default_rng(seed))
    return point, float(result.confidence_interval.low), float(result.confidence_interval.high)


def iqm_with_ci(values: np.ndarray, confidence: float = 0.95, resamples: int = 2000, seed: int = 0
                ) -> tuple[float, float, float]:
    """IQM of 1-D `values` and its percentile-bootstrap confidence interval (`estimate_with_ci`)."""
    return estimate_with_ci(values, iqm, confidence, resamples, seed)


def stratified_iqm_with_ci(groups: Sequence[np.ndarray], confidence: float = 0.95, resamples: int = 2000,
                           seed: int = 0) -> tuple[float, float, float]:
    """IQM over the runs of several tasks pooled, with a stratified percentile-bootstrap CI (as rliable
    does): each resample draws runs with replacement *within* each task, so every task keeps its share
    of the runs and the interval reflects run-to-run noise, not which tasks a resample happened to draw."""
    groups = [g[np.isfinite(g)] for g in (np.asarray(g, dtype=np.float64) for g in groups)]
    groups = [g for g in groups if len(g)]
    if not groups:
        return float("nan"), float("nan"), float("nan")
    pooled = np.concatenate(groups)
    point = float(iqm(pooled))
    if all(len(g) < 2 for g in groups) or np.ptp(pooled) == 0:
        return point, point, point
    rng = np.random.default_rng(seed)
    draws = np.concatenate([g[rng.integers(0, len(g), (resamples, len(g)))] for g in groups], axis=1)
    low, high = np.percentile(iqm(draws, axis=1), [50 * (1 - confidence), 50 * (1 + confidence)])
    return point, float(low), float(high)


def window_means(curves: np.ndarray, k: int) -> np.ndarray:
    """Means over every `k` consecutive shots of score-vs-shot curves (shots on the last axis); `k`
    longer than the curves means the whole curve."""
    curves = np.asarray(curves, dtype=np.float64)
    return sliding_window_view(curves, max(1, min(k, curves.shape[-1])), axis=-1).mean(axis=-1)


def best_k_plateau(curve: np.ndarray, k: int) -> tuple[float, int]:
    """The best mean over `k` consecutive shots of a score-vs-shot `curve`, and the shot it starts at:
    the paper's converged ("best k-shot") score. `k` longer than the curve means the whole curve."""
    means = window_means(curve, k)
    start = int(np.nanargmax(means))
    return float(means[start]), start


def converged_gap_with_ci(pairs: Sequence[tuple[np.ndarray, np.ndarray]], k: int, paired: bool,
                          confidence: float = 0.95, resamples: int = 2000, seed: int = 0, same_window: bool = False,
                          shots: tuple[int, int] | None = None) -> tuple[float, float, float]:
    """The mean over tasks of converged(a) − converged(b), for one ``(a, b)`` pair of ``[runs, shots]``
    arrays per task (converged: the best `k`-shot plateau of the mean curve over runs), and its
    percentile-bootstrap confidence interval. With `same_window`, b's converged is its mean over the
    shots of a's best window, not its own best: for an ablation of a (the same model fed zero rewards),
    whose own best window could hold shots (a probe) that a's converged leaves out.

    The bootstrap resamples runs within each task (a stratified bootstrap); with `paired`, row i of
    `a` and of `b` are the same seed and are resampled together, which keeps the seeds' own spread
    (e.g. Meta-World's hidden goals) out of the interval. Curves are cut to the shots both arrays of a
    pair have. With fewer than 2 runs in some sample there is nothing to resample: the interval is
    the point itself. `shots` ``(first, last)``, 1-based and inclusive: a fixed window instead, each array's mean
    over those shots (a gap that means the same whatever the curves look like).
    """
    common = [min(a.shape[1], b.shape[1]) for a, b in pairs]
    if shots is not None:
        check_shot_window(shots, min(common))
        pairs = [(a[:, shots[0] - 1 : shots[1]], b[:, shots[0] - 1 : shots[1]]) for a, b in pairs]
        k, same_window = shots[1] - shots[0] + 1, False  # one window of all its shots: the same for both
    else:
        pairs = [(a[:, :n], b[:, :n]) for (a, b), n in zip(pairs, common, strict=True)]
    if paired and any(len(a) != len(b) for a, b in pairs):
        raise ValueError("paired runs need as many runs in a as in b, row i of both being one seed")
    # What is resampled is run indices: one sample per pair when paired, else one per array.
    if paired:
        samples = [np.arange(len(a)) for a, _ in pairs]
        which = [(i, i) for i in range(len(pairs))]
    else:
        samples = [np.arange(len(runs)) for pair in pairs for runs in pair]
        which = [(2 * i, 2 * i + 1) for i in range(len(pairs))]

    def gap(*indices: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.mean([_converged_difference(a[indices[i]], b[indices[j]], k, same_window)
                        for (a, b), (i, j) in zip(pairs, which, strict=True)], axis=0)

    point = float(gap(*samples))
    if min(len(s) for s in samples) < 2:
        return point, point, point
    result = bootstrap(samples, gap, confidence_level=confidence, n_resamples=resamples, method="percentile",
                       vectorized=True, axis=-1, random_state=np.random.default_rng(seed))
    return point, float(result.confidence_interval.low), float(result.confidence_interval.high)


def check_shot_window(shots: tuple[int, int], available: int) -> None:
    """A ValueError unless ``shots = (first, last)`` is a window of shots 1..`available`."""
    first, last = shots
    if not 1 <= first <= last <= available:
        raise ValueError(f"the shot window {first}-{last} must lie within the shots the runs have, 1-{available}, "
                         "first <= last")


def _converged_difference(a: np.ndarray, b: np.ndarray, k: int, same_window: bool) -> np.ndarray:
    """converged(a) − converged(b) of ``[..., runs, shots]`` arrays (leading axes: bootstrap resamples): the
    best k-shot plateau of each mean curve, or with `same_window` b's mean over a's best window."""
    windows_a, windows_b = window_means(a.mean(axis=-2), k), window_means(b.mean(axis=-2), k)
    if not same_window:
        return windows_a.max(axis=-1) - windows_b.max(axis=-1)
    best = windows_a.argmax(axis=-1)[..., None]
    return (np.take_along_axis(windows_a, best, axis=-1) - np.take_along_axis(windows_b, best, axis=-1))[..., 0]
