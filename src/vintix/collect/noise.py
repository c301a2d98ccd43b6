"""Continuous noise distillation (paper Algorithm 1 and Appendix A.3).

A learning history is one long multi-episode run whose actions blend the demonstrator's action with
uniform noise, `a = (1 − ε)·π_D(s) + ε·u`, while ε anneals from 1 to 0. Episode returns then rise
from random to demonstrator level, a proxy of an RL learning history that AD can distil.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vintix.fields import check_field_types


@dataclass(frozen=True)
class NoiseSchedule:
    """ε(n) = (1 − (n / ((1 − f)·N))^p)^(1/p) for n ≤ (1 − f)·N, else 0."""

    curvature: float = 1.0
    """p: > 1 keeps ε high for longer, then drops it (for returns that rise early); < 1 the opposite."""
    noise_free_fraction: float = 0.0
    """f: the fraction of the history, at its end, played by the demonstrator alone (1: all of it,
    expert data for the expert-distillation baseline)."""

    def __post_init__(self) -> None:
        check_field_types(self, ValueError)  # recipes are YAML: "fast" must not reach a comparison
        if self.curvature <= 0:
            raise ValueError(f"noise schedule curvature p must be > 0, got {self.curvature}")
        if not 0 <= self.noise_free_fraction <= 1:
            raise ValueError(f"noise_free_fraction f must lie in [0, 1], got {self.noise_free_fraction}")

    def epsilon(self, step: np.ndarray | int, total_steps: int) -> np.ndarray:
        """ε at step index `step` (0-based) of a history of `total_steps` steps."""
        if self.noise_free_fraction == 1:
            return np.zeros(np.shape(step))
        progress = np.asarray(step, dtype=np.float64) / ((1 - self.noise_free_fraction) * total_steps)
        p = self.curvature
        return np.where(progress <= 1, (1 - np.clip(progress, 0, 1) ** p) ** (1 / p), 0.0)


def mix_action(expert: np.ndarray, epsilon: float, noise: np.ndarray) -> np.ndarray:
    """`(1 − ε)·expert + ε·u` for `noise` u drawn uniformly inside the action bounds; with the expert
    action inside them too, the blend (a convex combination) stays inside."""
    return (1 - epsilon) * expert + epsilon * noise
