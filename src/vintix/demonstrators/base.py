"""What a demonstrator is to the collector: a batched policy over a set of envs of one task."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

import gymnasium as gym
import numpy as np

from vintix.errors import VintixError
from vintix.tasks import get_task


class Demonstrator(Protocol):
    """An expert policy, evaluated on a batch of envs at once."""

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        """Actions [n_envs, act_dim] for observations [n_envs, obs_dim] of `envs` (deterministic)."""
        ...


def load_demonstrator(task: str, weights: Path | None = None) -> Demonstrator:
    """The project's demonstrator for `task`: Meta-World's scripted expert, or the trained policy
    shipped for the task's group (or the one in `weights`, a folder of trained weights); a clear error for
    tasks that have none."""
    spec = get_task(task)
    if weights is not None and spec.domain in ("metaworld", "bidexhands"):
        raise VintixError(f"{spec.name!r} has no trained demonstrator to load from {weights}: Meta-World's "
                          "are scripted and Bi-DexHands' need IsaacGym; leave the weights out")
    if spec.domain == "metaworld":
        from vintix.demonstrators.scripted import ScriptedMetaWorldDemonstrator

        return ScriptedMetaWorldDemonstrator(spec.name)
    if spec.domain == "bidexhands":
        raise VintixError(f"no demonstrator for Bi-DexHands task {spec.name!r}: its envs need IsaacGym")
    from vintix.demonstrators.trained import TrainedDemonstrator

    return TrainedDemonstrator(spec, weights)
