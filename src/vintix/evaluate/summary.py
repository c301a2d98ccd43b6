"""Aggregates of normalized scores: IQM with bootstrap confidence intervals, best-k-shot plateau."""

from __future__ import annotations

import numpy as np
from scipy.stats import bootstrap, trim_mean


def iqm(values: np.ndarray, axis: int = 0) -> np.ndarray:
    """Interquartile mean (the mean of the middle 50 %), robust to a few failed runs."""
    return trim_mean(values, 0.25, axis=axis)


def iqm_with_ci(values: np.ndarray, confidence: float = 0.95, resamples: int = 2000, seed: int = 0
                ) -> tuple[float, float, float]:
    """IQM of 1-D `values` and its percentile-bootstrap confidence interval over the values.
    With fewer than 2 values there is nothing to resample: the interval is the point itself."""
    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    if len(values) == 0:
        return float("nan"), float("nan"), float("nan")
    point = float(iqm(values))
    if len(values) < 2 or np.ptp(values) == 0:
        return point, point, point
    result = bootstrap((values,), iqm, confidence_level=confidence, n_resamples=resamples, method="percentile",
                       vectorized=True, axis=-1, random_state=np.random.default_rng(seed))
    return point, float(result.confidence_interval.low), float(result.confidence_interval.high)


def best_k_plateau(curve: np.ndarray, k: int) -> tuple[float, int]:
    """The best mean over `k` consecutive shots of a score-vs-shot `curve`, and the shot it starts at:
    the paper's converged ("best k-shot") score. `k` longer than the curve means the whole curve."""
    curve = np.asarray(curve, dtype=np.float64)
    k = max(1, min(k, len(curve)))
    window_means = np.convolve(curve, np.ones(k) / k, mode="valid")
    start = int(np.nanargmax(window_means))
    return float(window_means[start]), start
