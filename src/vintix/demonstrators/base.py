"""What a demonstrator is to the collector: a batched policy over a set of envs of one task."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import gymnasium as gym
import numpy as np

from vintix.tasks import get_task


class Demonstrator(Protocol):
    """An expert policy, evaluated on a batch of envs at once."""

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        """Actions [n_envs, act_dim] for observations [n_envs, obs_dim] of `envs` (deterministic)."""
        ...


def load_demonstrator(task: str) -> Demonstrator:
    """The project's demonstrator for `task`; a clear error for tasks that have none yet."""
    spec = get_task(task)
    if spec.domain == "metaworld":
        from vintix.demonstrators.scripted import ScriptedMetaWorldDemonstrator

        return ScriptedMetaWorldDemonstrator(spec.name)
    raise NotImplementedError(
        f"no demonstrator for {spec.domain} task {spec.name!r} yet: only Meta-World's scripted experts ship "
        "so far (trained MuJoCo and Industrial Benchmark demonstrators are still to come)."
    )
