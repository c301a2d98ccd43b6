"""A demonstrator that does not see the hidden goal: it infers it from the rewards it earns.

A goal-aware expert's noisy actions leak the goal: a model trained on its histories can copy the
goal out of the previous actions and never needs a reward, and at test time its own actions carry
no such information. This demonstrator knows only what the rewards so far revealed.

Posterior sampling over goals (Thompson sampling, as in PSRL): each env keeps candidate goals drawn
from the task's goal prior, each weighted by how well it explains every reward seen so far (the
task's own reward function with that goal swapped in, `rewards_under_goals`, against the reward
observed, with a Gaussian tolerance since no candidate is exactly the true goal). At the start of
every episode it draws one candidate from that posterior and plays the task's expert aimed at it for
the whole episode, so the first episode of a history is a guess from the prior and later ones home
in as fast as the rewards allow. With `probe_steps` (behaviour 'probing'), the first episode instead
visits corners of the goal box (or, with `probe_margin`, corners that far outside it) in a fixed
order and later episodes aim at the most likely goal: then the behaviour is a deterministic function
of the rewards so far, which a model trained to predict the mean action can imitate (a guess drawn at
random cannot be: its mean is the prior's middle). Behaviour 'probe-then-sample'
probes the same way and then aims each later episode at a goal drawn from the posterior: its episodes
after the probe are imperfect and home in, as a model's own do, so a context never holds only perfect
episodes that a model could copy instead of reading the rewards. Between episodes the
candidates are resampled by weight and jittered a little (a regularized particle filter), so they
gather around the goal and can end nearer to it than any of the first draws: Meta-World's reach
needs the hand within 5 cm of the goal, and 256 draws from its goal box leave the nearest about
1.5 cm away. What it proposes as the training target
(`demonstrator_action`) is the goal-aware expert's action: the action that is right given the
true goal, which a model can only match by inferring the goal from the context's rewards. With
`probe_target`, the target of the probing first episode is the probe itself: with nothing seen yet
the probe is the right action, and a goal-aware one could only be learned as the prior's middle.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Protocol, runtime_checkable

import gymnasium as gym
import numpy as np

from vintix.demonstrators.base import Demonstrator


class GoalConditionedExpert(Demonstrator, Protocol):
    """An expert that can aim at a goal it is given instead of the env's true one."""

    def act_toward(self, observations: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """Actions [n_envs, act_dim] if the hidden goal of env i were ``goals[i]``."""
        ...


@runtime_checkable
class FumblingExpert(Protocol):
    """An expert of tasks with an object to handle, which knows how to mishandle it (a lapse's failure)."""

    def fumble(self, actions: np.ndarray) -> np.ndarray:
        """`actions` [n, act_dim] changed so that the object is not handled (Meta-World: the gripper held open)."""
        ...


@runtime_checkable
class GoalInferringDemonstrator(Demonstrator, Protocol):
    """A demonstrator that learns within a history: the collector tells it what each step earned."""

    def begin(self, envs: Sequence[gym.Env], rngs: Sequence[np.random.Generator]) -> None:
        """Forget everything: `envs` start their histories (each with its own random stream)."""
        ...

    def observe(self, env_index: int, env: gym.Env, action: np.ndarray, reward: float, episode_end: bool) -> None:
        """Env `env_index` took `action` and earned `reward` (called right after its step, before any reset)."""
        ...

    def expert_act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        """The goal-aware expert's actions: the training target the collector records."""
        ...


@dataclass
class PosteriorSettings:
    """How the goal posterior is kept."""

    candidates: int = 256
    """candidate goals per env, drawn from the task's goal prior"""
    reward_tolerance: float = 0.5
    """std of the Gaussian likelihood of an observed reward given a candidate's reward: the slack for
    candidates that are near, not at, the true goal (in the env's reward units)"""
    update_every: int = 5
    """steps between likelihood updates within an episode (each costs `candidates` reward calls);
    the last step of an episode always updates"""
    jitter: float = 0.3
    """std of the jitter after resampling, as a fraction of the candidates' spread (per dimension)"""
    probe_steps: int = 0
    """0: the first episode aims at a goal drawn from the prior, like every later one. N > 0: it visits
    corners of the prior's box, N steps each, in a fixed order, and every later episode aims at the
    most likely goal rather than a drawn one: a behaviour that is a deterministic function of the
    rewards so far, which a model predicting the mean action can imitate"""
    min_jitter: float = 0.05
    """least jitter, as a fraction of the prior's spread: a posterior collapsed onto one candidate
    still moves, so it keeps searching around it"""
    sample_after_probe: bool = False
    """with probe_steps: later episodes aim at a goal drawn from the posterior, not the most likely one"""
    probe_target: bool = False
    """with probe_steps: the training target of the probing first episode is the probe, not the
    goal-aware expert's action"""
    probe_margin: float = 0.0
    """with probe_steps: how far outside the goal box the probed corners lie, per side (in the goal's
    units), so that the probe passes through fewer goals by chance while its rewards still place them.
    Meta-World reach, probe-then-sample, 20 unseen goals: the probing episode succeeds on 0.50 of them
    at 0, on 0.25 at 0.06 m, and the 7 episodes after it return 708-819 and 779-812"""
    probe_low_end: bool = False
    """with probe_steps: the probe aims at the goal box's low corner for the whole first episode instead of
    visiting corners (HalfCheetah-Vel stands still, and each reward is minus the target speed less the control
    cost). A model cannot copy a probe that switches corners mid-episode where nothing in the observation says
    when: it has no clock (`step_num` only marks episode starts). On HalfCheetah-Vel's two-end probe (3 m/s
    for 100 steps, then 0) the model ran 2.2-2.7 m/s through its own, never read the rewards it had learned to
    read, and scored the same with rewards as fed zeros; prompted with the demonstrator's probe, it ran at the
    target speed"""
    search: bool = False
    """sparse rewards: a search instead of a draw. The candidates are the same for every history (drawn with
    `SEARCH_SEED`) and ordered as a tour from the one nearest the goal box's centre; every step aims at the first
    one not ruled out, and a candidate is ruled out for good once its reward differs from the reward seen by
    more than `reward_tolerance`. So each episode continues the sweep where the last one stopped, and once a
    reward is paid only the candidates that explain it remain and every episode goes there: a deterministic
    function of the rewards so far, as a model can imitate. Needs update_every 1 (a step that is not weighed
    rules nothing out)"""
    lapse_probability: float = 0.0
    """with sample_after_probe: the chance that an episode after the first aimed one is a lapse, a clean episode
    that fails: aimed at a goal drawn from the prior, or, for an expert that handles an object (`fumble`), aimed
    at its guess with the object mishandled (either with equal chance). Later episodes aim at the posterior
    again, and every target stays the goal-aware expert's action, so the episode after a failure is never its
    copy: a model that learned to repeat its last episode repeats its own failures for good"""


SEARCH_SEED = 0
"""Seed of the candidates of `PosteriorSettings.search`: one set, and one search order, for every history."""


def search_order(candidates: np.ndarray, start: np.ndarray) -> np.ndarray:
    """`candidates` [n, goal_dim] reordered as a greedy nearest-neighbour tour that begins at the one nearest
    `start`: a sweep that walks from each candidate to the nearest one not visited yet."""
    left = list(range(len(candidates)))
    here, tour = start, []
    while left:
        nearest = left[int(np.argmin(np.linalg.norm(candidates[left] - here, axis=1)))]
        left.remove(nearest)
        tour.append(nearest)
        here = candidates[nearest]
    return candidates[tour]


# Per encoder group of hidden-goal tasks: Meta-World rewards lie in [0, 10], the toy task's in [0, 1];
# the hidden Reacher's give minus the fingertip's distance to the target (m), exactly (its control cost is
# the action's, which the reward under each candidate includes).
# The meta-RL tasks (keyed by their goal-aware experts' names, `expert_name`) pay exactly the reward under each
# candidate too; a direction is -1 or +1, so their candidates are never jittered off those two.
DEFAULT_SETTINGS = {"metaworld": PosteriorSettings(),
                    "point-goal": PosteriorSettings(reward_tolerance=0.05, update_every=1),
                    "mujoco-reacher-hidden": PosteriorSettings(reward_tolerance=0.005, update_every=1),
                    "halfcheetah-vel": PosteriorSettings(reward_tolerance=0.05, update_every=1, probe_low_end=True),
                    "halfcheetah-dir": PosteriorSettings(reward_tolerance=0.05, update_every=1, jitter=0.0,
                                                         min_jitter=0.0),
                    "ant-dir": PosteriorSettings(reward_tolerance=0.05, update_every=1, jitter=0.0, min_jitter=0.0)}

# Steps at each probed corner, per group, so that the probe fills the first episode: Meta-World's 3-D
# goal boxes have 4 corners to probe (a tetrahedron) in a 100-step episode, the toy's range 2 ends in 10,
# the hidden Reacher's square 2 opposite corners (beyond the arm's reach: it sweeps at full stretch) in 50, a
# meta-RL task's range its 2 ends in 200 (HalfCheetah-Vel only its low end, `PosteriorSettings.probe_low_end`).
PROBE_STEPS = {"metaworld": 25, "point-goal": 5, "mujoco-reacher-hidden": 25, "halfcheetah-vel": 100,
               "halfcheetah-dir": 100, "ant-dir": 100}

# The likelihood's tolerance of 'probe-then-sample', per group: 8 times the default, so that the episodes
# after the probe miss by a few centimetres on Meta-World reach (median end distance 4.7 cm in the second
# episode, 2.8 cm in the eighth, 20 goals) instead of 1.5-2 cm: near the errors a model makes, which its
# later episodes must correct from their rewards rather than repeat.
SAMPLE_AFTER_PROBE_TOLERANCE = {"metaworld": 4.0, "point-goal": 0.4, "mujoco-reacher-hidden": 0.04,
                                "halfcheetah-vel": 0.4, "halfcheetah-dir": 0.4, "ant-dir": 0.4}


def posterior_settings(group: str, behaviour: str, probe_margin: float = 0.0,
                       lapse_probability: float = 0.0, reward_tolerance: float = 0.0) -> PosteriorSettings:
    """The settings of `behaviour` ('posterior-sampling', 'posterior-search', 'probing' or 'probe-then-sample') on
    hidden-goal tasks of encoder group `group` (a meta-RL task: its expert's name), the probe's corners
    `probe_margin` outside the goal box (`PosteriorSettings.probe_margin`), with 'probe-then-sample' a lapse in an
    episode after the first aimed one at `lapse_probability`, and the likelihood's `reward_tolerance` instead of the
    behaviour's own where it is not 0."""
    settings = DEFAULT_SETTINGS[group]
    if behaviour == "posterior-search":  # every step weighed: a step that is not rules nothing out
        settings = replace(settings, search=True, update_every=1)
    elif behaviour != "posterior-sampling":
        settings = replace(settings, probe_steps=PROBE_STEPS[group], probe_margin=probe_margin)
    if behaviour == "probe-then-sample":
        settings = replace(settings, sample_after_probe=True, probe_target=True,
                           reward_tolerance=SAMPLE_AFTER_PROBE_TOLERANCE[group], lapse_probability=lapse_probability)
    return replace(settings, reward_tolerance=reward_tolerance) if reward_tolerance else settings


def _probe_corners(low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Corners of the box [low, high] to probe: both ends of a segment; in more dimensions the corners
    with an even number of coordinates at `high` (in 3-D a tetrahedron, from which distances fix a point)."""
    if len(low) == 1:
        return np.array([high, low])
    bits = np.array([[(i >> d) & 1 for d in range(len(low))] for i in range(2 ** len(low))])
    even = bits[bits.sum(axis=1) % 2 == 0]
    return np.where(even == 1, high, low)


class _GoalPosterior:
    """One env's candidate goals, their log-weights, and the goal it plays this episode."""

    def __init__(self, box: tuple[np.ndarray, np.ndarray], rng: np.random.Generator, settings: PosteriorSettings,
                 candidates: np.ndarray) -> None:
        self.candidates, self.rng, self.settings = candidates, rng, settings
        self.prior_draws = candidates.copy()  # what a lapse aims at: goals drawn from the prior
        self.log_weights = np.zeros(len(candidates))
        self.low, self.high = box
        self.min_jitter = settings.min_jitter * candidates.std(axis=0)
        self.steps, self.episode = 0, 0
        self.fumbling = False
        """whether this episode is a lapse that mishandles the object"""
        low, high = self.low - settings.probe_margin, self.high + settings.probe_margin
        self.corners = low[None] if settings.probe_low_end else _probe_corners(low, high)
        self.alive = np.ones(len(candidates), dtype=bool)
        """with `search`: the candidates no reward has ruled out"""
        self.guess = self._draw()

    @property
    def probing(self) -> bool:
        """Whether this step belongs to a probing first episode."""
        return bool(self.settings.probe_steps) and self.episode == 0

    def aim(self) -> np.ndarray:
        """The goal this step aims at: a probe corner in a probing first episode, else the episode's guess."""
        if self.probing:
            return self.corners[min(self.steps // self.settings.probe_steps, len(self.corners) - 1)]
        if self.settings.search:
            return self.candidates[np.argmax(self.alive)]
        return self.guess

    def update(self, candidate_rewards: np.ndarray, reward: float) -> None:
        if self.settings.search:
            self.alive &= np.abs(candidate_rewards - reward) <= self.settings.reward_tolerance
            if not self.alive.any():  # no candidate explains every reward (none close enough): search again
                self.alive[:] = True
            return
        self.log_weights -= 0.5 * ((candidate_rewards - reward) / self.settings.reward_tolerance) ** 2
        self.log_weights -= self.log_weights.max()  # keep the best candidate at weight 1 (no underflow)

    def _weights(self) -> np.ndarray:
        weights = np.exp(self.log_weights)
        return weights / weights.sum()

    def _draw(self) -> np.ndarray:
        return self.candidates[self.rng.choice(len(self.candidates), p=self._weights())]

    def next_episode(self, can_fumble: bool = False) -> None:
        """Draw the goal of the next episode, after resampling the candidates by weight and jittering
        them if the weights have degenerated (effective sample size below half); or, at the lapse
        probability, make the episode a lapse (`PosteriorSettings.lapse_probability`: with `can_fumble`, half
        of the lapses mishandle the object instead of aiming at a prior draw)."""
        weights = self._weights()
        if not self.settings.search and 1.0 / np.sum(weights**2) < len(weights) / 2:
            self._resample_and_jitter()
        aims_best = self.settings.probe_steps and not self.settings.sample_after_probe
        self.guess = self.candidates[np.argmax(self.log_weights)] if aims_best else self._draw()
        self.steps = 0
        self.episode += 1
        self.fumbling = False
        # No draw without lapses: histories collected before lapses existed keep their random stream, and bytes.
        lapses = self.settings.lapse_probability > 0 and self.episode >= 2
        if lapses and self.rng.random() < self.settings.lapse_probability:
            self.fumbling = can_fumble and bool(self.rng.random() < 0.5)
            if not self.fumbling:
                self.guess = self.prior_draws[self.rng.integers(len(self.prior_draws))]

    def _resample_and_jitter(self) -> None:
        chosen = self.candidates[self.rng.choice(len(self.candidates), size=len(self.candidates), p=self._weights())]
        scale = np.maximum(self.settings.jitter * chosen.std(axis=0), self.min_jitter)
        self.candidates = np.clip(chosen + self.rng.normal(size=chosen.shape) * scale, self.low, self.high)
        self.log_weights = np.zeros(len(self.candidates))


class PosteriorSamplingDemonstrator:
    """Plays a goal-conditioned expert aimed at a goal drawn, each episode, from the posterior over
    goals given the rewards seen so far (see the module docstring)."""

    def __init__(self, expert: GoalConditionedExpert, settings: PosteriorSettings) -> None:
        self.expert = expert
        self.settings = settings
        self._posteriors: list[_GoalPosterior] = []

    def begin(self, envs: Sequence[gym.Env], rngs: Sequence[np.random.Generator]) -> None:
        self._posteriors = [_GoalPosterior(env.unwrapped.goal_box(), rng, self.settings,  # type: ignore[attr-defined]
                                           self._candidates(env.unwrapped, rng))
                            for env, rng in zip(envs, rngs, strict=True)]

    def _candidates(self, env: gym.Env, rng: np.random.Generator) -> np.ndarray:
        """Goals drawn from the env's prior: the history's own draws, or with `search` one fixed tour for all."""
        if not self.settings.search:
            return env.goal_prior(rng, self.settings.candidates)  # type: ignore[attr-defined]
        draws = env.goal_prior(np.random.default_rng(SEARCH_SEED), self.settings.candidates)  # type: ignore[attr-defined]
        low, high = env.goal_box()  # type: ignore[attr-defined]
        return search_order(draws, (np.asarray(low) + np.asarray(high)) / 2)

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        if len(self._posteriors) != len(envs):
            raise RuntimeError("PosteriorSamplingDemonstrator.begin(envs, rngs) must come before act")
        actions = self.expert.act_toward(observations, np.stack([p.aim() for p in self._posteriors]))
        fumbling = np.array([p.fumbling for p in self._posteriors])
        if fumbling.any():
            actions[fumbling] = self.expert.fumble(actions[fumbling])  # type: ignore[attr-defined]
        return actions

    def expert_act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        expert = self.expert.act(observations, envs)
        if not self.settings.probe_target:
            return expert
        probing = np.array([p.probing for p in self._posteriors])
        return np.where(probing[:, None], self.act(observations, envs), expert)

    def observe(self, env_index: int, env: gym.Env, action: np.ndarray, reward: float, episode_end: bool) -> None:
        posterior = self._posteriors[env_index]
        posterior.steps += 1
        if episode_end or posterior.steps % self.settings.update_every == 0:
            rewards = env.unwrapped.rewards_under_goals(posterior.candidates, action)  # type: ignore[attr-defined]
            posterior.update(rewards, reward)
        if episode_end:
            posterior.next_episode(can_fumble=isinstance(self.expert, FumblingExpert))
