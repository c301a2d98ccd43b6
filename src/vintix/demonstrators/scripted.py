"""Meta-World's scripted experts (`metaworld.policies`), one per task.

They read the goal from the last 3 observation entries, which the ML45 setting hides; the env
gives the true goal to demonstrators through `expert_observation`. The model never sees it.
"""

from __future__ import annotations

from collections.abc import Sequence

import gymnasium as gym
import numpy as np
from metaworld.policies import ENV_POLICY_MAP


class ScriptedMetaWorldDemonstrator:
    """The scripted policy of one Meta-World task."""

    def __init__(self, task: str) -> None:
        self.policy = ENV_POLICY_MAP[task]()

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        return np.stack([
            self.policy.get_action(env.unwrapped.expert_observation(obs))  # type: ignore[attr-defined]
            for obs, env in zip(observations, envs)
        ])
