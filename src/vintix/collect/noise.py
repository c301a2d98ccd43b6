"""Continuous noise distillation (paper Algorithm 1 and Appendix A.3).

A learning history is one long multi-episode run whose actions blend the demonstrator's action with
uniform noise, `a = (1 − ε)·π_D(s) + ε·u`, while ε anneals from 1 to 0. Episode returns then rise
from random to demonstrator level, a proxy of an RL learning history that AD can distil.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import isotonic_regression

from vintix.fields import check_field_types


@dataclass(frozen=True)
class NoiseSchedule:
    """ε(n) = (1 − (x(n))^p)^(1/p) over the noised part s·N ≤ n ≤ (1 − f)·N of a history of N steps,
    x(n) = (n − s·N) / ((1 − s − f)·N), else 0; or, with `knots`, ε piecewise linear through them over
    the same part."""

    curvature: float = 1.0
    """p: > 1 keeps ε high for longer, then drops it (for returns that rise early); < 1 the opposite."""
    noise_free_fraction: float = 0.05
    """f: the fraction of the history, at its end, played by the demonstrator alone (1: all of it,
    expert data for the expert-distillation baseline); 0.05 unless given, in Python, the CLI and recipes alike."""
    knots: tuple[float, ...] = ()
    """ε at evenly spaced points of the noised part of the history, falling to 0 from 1 (or from less,
    so that its noisiest episodes still act), instead of the curvature (`fit_knots` places them so the
    expected return rises linearly); empty: the power law."""
    pilot_steps: int = 0
    """Steps the demonstrator plays under linear decay on each history's own env before the history
    (not stored), to fit that history's knots; for tasks whose variants answer ε differently (Meta-World
    goals). 0: no pilot, one schedule for every history."""
    noise_free_start_fraction: float = 0.0
    """s: the fraction of the history, at its start, played by the demonstrator alone, for a
    demonstrator whose first episode gathers what the rest reads from its rewards (a probe)."""
    level: float | None = None
    """ε held at this level over the whole noised part instead of annealing: DPT's contexts (1.0: uniformly random
    actions, whose rewards alone say where the goal is; the recorded target stays the goal-aware expert's action),
    or a constant ε-noise around the expert (its actions then hint at the goal); None: annealed."""

    def __post_init__(self) -> None:
        check_field_types(self, ValueError)  # recipes are YAML: "fast" must not reach a comparison
        if self.curvature <= 0:
            raise ValueError(f"noise schedule curvature p must be > 0, got {self.curvature}")
        if not 0 <= self.noise_free_fraction <= 1:
            raise ValueError(f"noise_free_fraction f must lie in [0, 1], got {self.noise_free_fraction}")
        start, tail = self.noise_free_start_fraction, self.noise_free_fraction
        if not (start == 0 or 0 < start < 1 - tail):
            raise ValueError(f"noise_free_start_fraction s must lie in [0, 1 − f) so that some of the history is "
                             f"noised (f = noise_free_fraction = {tail}), got {start}")
        if self.pilot_steps < 0:
            raise ValueError(f"noise schedule pilot_steps must be >= 0, got {self.pilot_steps}")
        annealed = self.knots or self.pilot_steps or self.curvature != 1
        if self.level is not None and (not 0 < self.level <= 1 or annealed):
            raise ValueError(f"noise schedule level must lie in (0, 1] and replaces the annealing: give it without "
                             f"knots, pilot_steps or a curvature; got level={self.level}")
        if self.pilot_steps and self.curvature != 1:
            raise ValueError("give noise schedule pilot_steps or a curvature, not both (the pilot fits knots, "
                             "which replace the power law)")
        if self.knots:
            knots = np.asarray(self.knots, dtype=np.float64)
            if len(knots) < 2 or not 0 < knots[0] <= 1 or knots[-1] != 0 or np.any(np.diff(knots) > 0):
                raise ValueError(f"noise schedule knots must fall to 0 from at most 1 (at least two, never rising), "
                                 f"got {list(self.knots)}")
            if self.curvature != 1:
                raise ValueError("give noise schedule knots or a curvature, not both (knots replace the power law)")

    def epsilon(self, step: np.ndarray | int, total_steps: int) -> np.ndarray:
        """ε at step index `step` (0-based) of a history of `total_steps` steps."""
        if self.noise_free_fraction == 1:
            return np.zeros(np.shape(step))
        start = self.noise_free_start_fraction * total_steps
        end = (1 - self.noise_free_fraction) * total_steps
        progress = (np.asarray(step, dtype=np.float64) - start) / (end - start)
        clipped = np.clip(progress, 0, 1)
        if self.level is not None:
            noised = np.full(clipped.shape, self.level)
        elif self.knots:
            noised = np.interp(clipped, np.linspace(0, 1, len(self.knots)), self.knots)
        else:
            p = self.curvature
            noised = (1 - clipped ** p) ** (1 / p)
        return np.where((progress >= 0) & (progress <= 1), noised, 0.0)

    def recorded(self) -> dict[str, Any]:
        """The schedule as a history file records it (root attributes; knots, pilot, noise-free start and level only
        when it has them)."""
        settings: dict[str, Any] = {"curvature": self.curvature, "noise_free_fraction": self.noise_free_fraction}
        settings |= {"knots": list(self.knots)} if self.knots else {}
        start = self.noise_free_start_fraction
        settings |= {"noise_free_start_fraction": start} if start else {}
        settings |= {"level": self.level} if self.level is not None else {}
        return settings | ({"pilot_steps": self.pilot_steps} if self.pilot_steps else {})

    @classmethod
    def from_recorded(cls, attrs: Mapping[str, Any]) -> NoiseSchedule:
        """The schedule a history file records (see `recorded`)."""
        return cls(float(attrs["curvature"]), float(attrs["noise_free_fraction"]),
                   tuple(float(k) for k in np.ravel(attrs.get("knots", []))), int(attrs.get("pilot_steps", 0)),
                   float(attrs.get("noise_free_start_fraction", 0.0)),
                   None if "level" not in attrs else float(attrs["level"]))


def epsilon_greedy(expert: np.ndarray, epsilon: np.ndarray, noise: np.ndarray, actions: int) -> np.ndarray:
    """AD^ε's noise on discrete actions (the discrete form of Algorithm 1): the expert's action, or with probability
    ε a uniformly random one of the `actions`. `noise` ``[..., 2]`` holds two uniform [0, 1) draws per row, the coin
    and the random action, so a history's noise stream does not depend on its ε."""
    coin, pick = noise[..., 0], noise[..., 1]
    random_action = np.minimum((pick * actions).astype(np.int64), actions - 1)
    return np.where(coin < epsilon, random_action, expert).astype(np.int64)


def mix_action(expert: np.ndarray, epsilon: float | np.ndarray, noise: np.ndarray) -> np.ndarray:
    """`(1 − ε)·expert + ε·u` for `noise` u drawn uniformly inside the action bounds (ε a number, or one
    per row as a column); with the expert action inside them too, the blend (a convex combination)
    stays inside."""
    # (1 − ε) in the expert's precision, as numpy multiplies a float32 array by a Python float: a
    # per-row ε then gives the same bytes as the one-number ε of histories collected before it.
    return np.asarray(1 - epsilon, dtype=expert.dtype) * expert + epsilon * noise


def fit_knots(epsilons: np.ndarray, returns: np.ndarray, steps: np.ndarray, count: int = 11,
              groups: int = 20) -> tuple[float, ...]:
    """Knots of a schedule whose expected return rises linearly from random to demonstrator level.

    From episodes played at (mean) noise `epsilons` with `returns` over `steps` steps each: the
    episodes, sorted by ε, are pooled into `groups` of about equal steps (so the fit is finest where
    the data are densest, which a schedule fitted once makes near the ε where return changes); a
    weighted isotonic fit makes return fall with ε; knot k is the ε where that fit reaches the
    fraction k / (count − 1) of the way from its level at the most noise to its level at the least.
    A task whose return jumps at some ε then spends most of its history near that ε.
    """
    if len(returns) == 0:
        raise ValueError("no complete episode to fit knots to (histories shorter than an episode?)")
    order = np.argsort(epsilons, kind="stable")
    epsilons, returns, steps = (np.asarray(a, dtype=np.float64)[order] for a in (epsilons, returns, steps))
    group = np.minimum((np.cumsum(steps) - steps) * groups // steps.sum(), groups - 1).astype(int)
    weight = np.bincount(group, steps)
    filled = weight > 0
    centre = (np.bincount(group, steps * epsilons) / np.where(filled, weight, 1))[filled]
    level = (np.bincount(group, steps * returns) / np.where(filled, weight, 1))[filled]
    fitted = isotonic_regression(level, weights=weight[filled], increasing=False).x
    if len(fitted) < 2 or fitted[0] <= fitted[-1]:
        raise ValueError(f"return does not fall with noise in these {len(returns)} episodes: nothing to fit knots to")
    targets = fitted[-1] + np.linspace(0, 1, count) * (fitted[0] - fitted[-1])
    # np.interp needs rising x: walk the fit from most noise to least.
    knots = np.interp(targets, fitted[::-1], centre[::-1])
    knots[0], knots[-1] = 1.0, 0.0
    return tuple(float(k) for k in np.round(np.minimum.accumulate(knots), 3))
