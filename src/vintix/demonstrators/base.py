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


BEHAVIOURS = ("expert", "posterior-sampling", "probing")
"""How a demonstrator plays a history: as the goal-aware expert, or without the goal, inferring it from
rewards (`vintix.demonstrators.posterior`): aiming each episode at a goal drawn from its posterior, or
probing the goal box's corners in the first episode and aiming later ones at the likeliest goal."""


def load_demonstrator(task: str, weights: Path | None = None, behaviour: str = "expert") -> Demonstrator:
    """The project's demonstrator for `task`: Meta-World's scripted expert, or the trained policy
    shipped for the task's group (or the one in `weights`, a folder of trained weights); a clear error for
    tasks that have none. `behaviour="posterior-sampling"` or `"probing"` wraps a scripted expert of a
    hidden-goal task (Meta-World, toy) in a demonstrator that does not see the goal and infers it from rewards."""
    spec = get_task(task)
    if behaviour not in BEHAVIOURS:
        raise VintixError(f"unknown demonstrator behaviour {behaviour!r}; choose one of {', '.join(BEHAVIOURS)}")
    if behaviour != "expert":
        from vintix.demonstrators.posterior import DEFAULT_SETTINGS, PosteriorSamplingDemonstrator, posterior_settings

        if spec.domain not in DEFAULT_SETTINGS or weights is not None:
            raise VintixError(f"{spec.name!r}: {behaviour} needs a scripted expert that can aim at a given goal "
                              f"(tasks of {', '.join(sorted(DEFAULT_SETTINGS))}), not a {spec.domain} task"
                              f"{' or trained weights' if weights is not None else ''}; use behaviour 'expert'")
        expert = load_demonstrator(spec.name)
        return PosteriorSamplingDemonstrator(expert, posterior_settings(spec.domain, behaviour))  # type: ignore[arg-type]
    if weights is not None and spec.domain in ("metaworld", "bidexhands"):
        raise VintixError(f"{spec.name!r} has no trained demonstrator to load from {weights}: Meta-World's "
                          "are scripted and Bi-DexHands' need IsaacGym; leave the weights out")
    if spec.domain == "metaworld":
        from vintix.demonstrators.scripted import ScriptedMetaWorldDemonstrator

        return ScriptedMetaWorldDemonstrator(spec.name)
    if spec.domain == "toy":
        from vintix.demonstrators.scripted import ScriptedPointGoalDemonstrator

        return ScriptedPointGoalDemonstrator()
    if spec.domain == "bidexhands":
        raise VintixError(f"no demonstrator for Bi-DexHands task {spec.name!r}: its envs need IsaacGym")
    from vintix.demonstrators.trained import TrainedDemonstrator

    return TrainedDemonstrator(spec, weights)
