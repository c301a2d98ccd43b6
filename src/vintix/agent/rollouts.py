"""A model's own rollouts, relabelled with the goal-aware expert's actions (DAgger for DPT's target).

A model trained on DPT's target (the goal-aware expert's action behind contexts of random actions) meets, at play,
contexts it never saw in training: its own episodes, which improve as it learns where the goal is. DAgger closes that
gap: the model plays histories on training goals, each row records the expert's action as its target, the histories
join the data, and the model trains again. Nothing beyond the env's true goal and its expert is needed.

`ModelRollouts` is the collector's demonstrator for such histories (`vintix collect --rollouts-of CHECKPOINT`): the
model plays (its actions sampled, as at play), the collector records what the expert would have done.
"""

from __future__ import annotations

from collections.abc import Sequence

import gymnasium as gym
import numpy as np

from vintix.agent.agent import Agent
from vintix.agent.pretrained import resolve_checkpoint
from vintix.demonstrators import Demonstrator, load_demonstrator
from vintix.tasks import action_space_of

ROLLOUTS_SOURCE = "rollouts:"
"""How a history's recorded ``demonstrator`` names the model that played it (`CollectionPlan.demonstrator`)."""


class ModelRollouts:
    """Plays a model's agent on a batch of envs (the collector's `GoalInferringDemonstrator`): its actions are the
    history's, and the task's goal-aware expert's are the recorded target: the package's expert, or `expert`, a
    recipe's ``demonstrator:`` source (your own). The model and the expert load in the process that plays (`begin`),
    so the demonstrator travels to collection workers as names."""

    def __init__(self, checkpoint: str, task: str, expert: str | None = None, trust_code: bool = False) -> None:
        self.checkpoint, self.task, self.trust_code = str(resolve_checkpoint(checkpoint)), task, trust_code
        self.expert = expert
        self._agent: Agent | None = None
        self._expert: Demonstrator | None = None
        self._rewards = np.zeros(0)
        self._starts = np.zeros(0, dtype=bool)

    @property
    def source(self) -> str:
        """What a history records as its demonstrator."""
        return f"{ROLLOUTS_SOURCE}{self.checkpoint}"

    def begin(self, envs: Sequence[gym.Env], rngs: Sequence[np.random.Generator]) -> None:
        if self._agent is None:
            self._agent = Agent.from_pretrained(self.checkpoint, threads=1, trust_code=self.trust_code)
            self._expert = load_demonstrator(self.task, source=self.expert)
        # The batch's first stream seeds the agent's draws: a history's rollout depends on its batch's seeds only.
        self._agent.seed = int(rngs[0].integers(2**31))
        spaces = [action_space_of(env.action_space) for env in envs]
        self._agent.reset([self.task] * len(envs), spaces, discard_context=True)
        self._rewards = np.zeros(len(envs))
        self._starts = np.ones(len(envs), dtype=bool)

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        assert self._agent is not None, "begin() first"
        actions = self._agent.act(list(observations), self._rewards, self._starts)
        self._starts[:] = False
        return np.stack(actions)

    def observe(self, env_index: int, env: gym.Env, action: np.ndarray, reward: float, episode_end: bool) -> None:
        self._rewards[env_index] = reward
        self._starts[env_index] = episode_end

    def expert_act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        assert self._expert is not None, "begin() first"
        return self._expert.act(observations, envs)
