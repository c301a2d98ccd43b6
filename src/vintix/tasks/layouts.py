"""Observation layouts of older env versions, built from the observations of the versions we run.

A model trained on gymnasium's MuJoCo ``-v4`` envs (the official Vintix release) reads observations in
their layout. The ``-v5`` envs we run drop channels that are constant in ``-v4`` (always 0: the world
body's inertia, velocity and external force, the root joint's actuator force, a 2-D reacher's z
distance, a double pendulum's second and third constraint force), and ``Ant-v5`` appends contact
forces that ``Ant-v4`` leaves out by default. Every ``-v4`` channel is therefore a ``-v5`` channel or a
constant 0, and an `ObsLayout` says which, so a ``-v4`` model acts on a ``-v5`` env exactly as on ``-v4``
(tests/test_official_checkpoint.py steps both versions from the same state and compares).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

Part = tuple[int, int] | int
"""A slice ``(start, stop)`` of the env's observation, or that many constant-zero channels."""


@dataclass(frozen=True)
class ObsLayout:
    """A model's observation channels in terms of an env's: ``channels[i]`` is the env channel that model
    channel ``i`` reads, or -1 for a channel the env does not have (always 0 in the model's version)."""

    env_dim: int
    """dimension of the env's own observations"""
    channels: tuple[int, ...]
    """for each model input channel, the env channel it reads; -1: a constant 0"""

    def __post_init__(self) -> None:
        bad = [c for c in self.channels if not -1 <= c < self.env_dim]
        if bad:
            raise ValueError(f"observation layout reads channels {bad[:5]} of a {self.env_dim}-dim observation")

    @classmethod
    def from_parts(cls, env_dim: int, parts: Sequence[Part]) -> ObsLayout:
        channels: list[int] = []
        for part in parts:
            channels += list(range(*part)) if isinstance(part, tuple) else [-1] * part
        return cls(env_dim, tuple(channels))

    @property
    def dim(self) -> int:
        """Dimension of the observations it builds (the model's)."""
        return len(self.channels)

    def apply(self, obs: np.ndarray) -> np.ndarray:
        """The model's observation(s) ``[..., dim]`` from the env's ``[..., env_dim]``."""
        index = np.asarray(self.channels)
        return np.where(index >= 0, np.take(obs, np.maximum(index, 0), axis=-1), 0.0).astype(obs.dtype)


_HUMANOID_V4_FROM_V5: tuple[Part, ...] = (
    (0, 45),  # qpos[2:], qvel
    10, (45, 175),  # cinert: the world body's 10, then 13 bodies
    6, (175, 253),  # cvel
    6, (253, 270),  # qfrc_actuator: the root free joint's 6, then 17 hinges
    6, (270, 348),  # cfrc_ext
)

_V4_FROM_V5: dict[tuple[str, int], tuple[int, tuple[Part, ...]]] = {
    # (our task, the model's obs dim): (our env's obs dim, parts)
    ("Humanoid-v5", 376): (348, _HUMANOID_V4_FROM_V5),
    ("HumanoidStandup-v5", 376): (348, _HUMANOID_V4_FROM_V5),
    ("Ant-v5", 27): (105, ((0, 27),)),  # qpos[2:], qvel; v5's 78 contact-force channels dropped
    ("Reacher-v5", 11): (10, ((0, 10), 1)),  # fingertip - target: v4 keeps the z (0 in the plane)
    ("InvertedDoublePendulum-v5", 11): (9, ((0, 9), 2)),  # qfrc_constraint: v4 keeps all three
}


def legacy_layout(task: str, model_obs_dim: int) -> ObsLayout | None:
    """How our env for `task` feeds a model that reads `model_obs_dim`-dim observations of an older
    version of it (``Humanoid-v5`` -> ``Humanoid-v4``'s 376 channels), or None where none is known."""
    known = _V4_FROM_V5.get((task, model_obs_dim))
    return None if known is None else ObsLayout.from_parts(*known)
