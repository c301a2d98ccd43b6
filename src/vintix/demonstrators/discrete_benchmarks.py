"""Demonstrators of the discrete benchmarks (`vintix.tasks.discrete_benchmarks`): the sources of learning histories
compared there.

- ``expert``: the goal-aware optimal policy (the shortest path to the goal; to the key, then the door; the best
  arm). With the collector's ε-greedy noise annealed from 1 to 0 along the history it plays AD^ε's histories
  (the discrete form of the paper's Algorithm 1).
- ``posterior-sampling``: a demonstrator that does not see what is hidden and infers it from its rewards, as
  `vintix.demonstrators.posterior` does on continuous tasks. In a room it keeps the cells its rewards have ruled
  out (a step that ends on a cell and earns nothing rules it out as the goal, the key, or the door with the key in
  hand), walks to a candidate drawn uniformly from the rest (the posterior, whose prior is every cell), draws
  another once that one is ruled out, and goes straight to what it has found; on the bandit it is Thompson
  sampling (a Beta posterior per arm).
- ``posterior-search`` (the rooms): the same posterior, searched in a fixed order: it walks to the first cell not
  ruled out along a spiral out of the room's centre (`SEARCH_ORDER`), so each episode goes on where the last one
  stopped, and its whole behaviour is a function of the rewards so far, with nothing drawn at random for a model to
  guess.
- ``walk-search`` (the rooms): searches by a persistent random walk (`WALK_PERSISTENCE`) and goes straight to what
  its rewards have shown. Slower than the spiral, but each move follows from what a model sees at that step: the
  position, the last move and the rewards so far, where the spiral's next cell depends on how far the search got
  in earlier episodes.
- ``learner``: AD's own histories, an RL algorithm learning from scratch on the history's env: tabular Q-learning
  in the rooms (its state: the cell and whether the episode has paid yet, which tells Key-to-Door's "key in
  hand" from its own rewards), UCB1 on the bandit (AD's source algorithm there).

Each follows the collector's `GoalInferringDemonstrator` protocol: told every step's reward, it plays the history,
and the goal-aware expert's action is what a history records as ``demonstrator_action``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from vintix.tasks.discrete_benchmarks import (
    MOVES,
    SIZE,
    START,
    BernoulliBanditEnv,
    DarkRoomEnv,
    GridEnv,
    KeyToDoorEnv,
    cells,
    step_towards,
)

ICRL_BEHAVIOURS = ("expert", "posterior-sampling", "posterior-search", "walk-search", "learner")
"""How a demonstrator plays a discrete benchmark's history (this module's docstring)."""


def _actions(env: gym.Env) -> int:
    return int(env.action_space.n)  # type: ignore[attr-defined]


def _room(env: gym.Env) -> GridEnv:
    """The room under `env`'s wrappers."""
    inner = env.unwrapped
    assert isinstance(inner, GridEnv), f"{inner} is not a room of vintix.tasks.discrete_benchmarks"
    return inner


def _expert_actions(envs: Sequence[gym.Env]) -> np.ndarray:
    return np.array([env.unwrapped.expert_action() for env in envs], dtype=np.int64)  # type: ignore[attr-defined]


class IcrlExpert:
    """The goal-aware optimal policy of a discrete benchmark (it reads the hidden goal off the env)."""

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        return _expert_actions(envs)


CELLS = cells()
"""Each cell's (x, y), by cell index."""


def spiral_order() -> np.ndarray:
    """Cell indices in the order of a spiral out of the room's centre: ring by ring (steps from the centre along the
    farther axis), each ring walked counter-clockwise from the right of the centre, so that consecutive cells of a
    ring are neighbours."""
    offset = CELLS - np.array(START)
    ring = np.abs(offset).max(axis=1)
    angle = np.arctan2(offset[:, 1], offset[:, 0]) % (2 * np.pi)  # counter-clockwise from the right
    return np.lexsort((angle, ring))


SEARCH_ORDER = spiral_order()
"""The order in which `posterior-search` walks the cells its rewards have not ruled out."""
SEARCHES = ("sample", "spiral", "walk")
"""How a room's demonstrator looks for what its rewards have not shown yet: walk to a candidate drawn from the
posterior (``posterior-sampling``), to the next along `SEARCH_ORDER` (``posterior-search``), or a random walk
(``walk-search``)."""
WALK_PERSISTENCE = 0.7
"""`walk-search`'s chance of repeating its last move where no wall stops it (else a move drawn among those that
do not bump into one). Of 0, 0.5, 0.7, 0.85 and 0.95 it found Key-to-Door's key and door soonest in a quick
simulation; the demonstrator on the first 100 held-out pairs scores 0.23, 0.46, 0.82, 0.96 and 1.00 of optimal in
episodes 1, 2, 5, 10 and 20 (the spiral's `posterior-search`: 0.36, 0.78, 1.00, 1.00, 1.00)."""


def _cell(position: np.ndarray) -> int:
    return int(position[1]) * SIZE + int(position[0])


def _position(cell: int) -> np.ndarray:
    return np.array([cell % SIZE, cell // SIZE])


@dataclass
class _RoomSearch:
    """One history's knowledge of a room: the cells ruled out as the goal (Key-to-Door: as the key, and as the
    door), what it has found, and the candidate it walks to."""

    rng: np.random.Generator
    ruled_out: np.ndarray
    """[2, cells]: row 0 the goal (Key-to-Door: the key), row 1 Key-to-Door's door"""
    found: list[int | None]
    target: list[int | None]
    search: str = "sample"
    """one of `SEARCHES`"""
    last_move: int = 0
    """the move just taken (0, staying, at an episode's start)"""
    paid: bool = False
    """whether this episode has paid yet (Key-to-Door: the key is in hand)"""

    @classmethod
    def new(cls, rng: np.random.Generator, search: str = "sample") -> _RoomSearch:
        return cls(rng, np.zeros((2, SIZE * SIZE), bool), [None, None], [None, None], search)

    def stage(self, env: GridEnv) -> int:
        """0 while looking for the goal (the key), 1 for Key-to-Door's door with the key in hand."""
        return int(isinstance(env, KeyToDoorEnv) and self.paid)

    def move(self, env: GridEnv) -> int:
        """The action: straight to what a reward has shown, else the search's next move."""
        if self.search == "walk" and self.found[self.stage(env)] is None:
            return self._walk(env.position)
        return int(step_towards(env.position, self.aim(env)))

    def _walk(self, position: np.ndarray) -> int:
        inside = ((position + MOVES >= 0) & (position + MOVES < SIZE)).all(axis=1)
        inside[0] = False  # staying put searches nothing
        if not (inside[self.last_move] and self.rng.random() < WALK_PERSISTENCE):
            self.last_move = int(self.rng.choice(np.flatnonzero(inside)))
        return self.last_move

    def aim(self, env: GridEnv) -> np.ndarray:
        stage = self.stage(env)
        if self.found[stage] is not None:
            return _position(self.found[stage])  # type: ignore[arg-type]
        target = self.target[stage]
        if target is None or self.ruled_out[stage, target]:
            # The posterior is uniform over the cells not ruled out: draw one to walk to, or take the next in order.
            if self.search == "spiral":
                target = int(SEARCH_ORDER[np.argmax(~self.ruled_out[stage, SEARCH_ORDER])])
            else:
                target = int(self.rng.choice(np.flatnonzero(~self.ruled_out[stage])))
            self.target[stage] = target
        return _position(target)

    def observe(self, env: GridEnv, action: int, reward: float, episode_end: bool) -> None:
        # The walk persists in the move taken, noise included: the one a model sees in its context. A new episode
        # starts without one, as the model's context marks it.
        self.last_move = 0 if episode_end else action
        cell, stage = _cell(env.position), self.stage(env)
        if reward > 0 and self.found[stage] is None:
            self.found[stage] = cell
            if isinstance(env, KeyToDoorEnv):  # the key and the door are distinct cells
                self.ruled_out[1 - stage, cell] = True
        elif reward == 0 and not (isinstance(env, DarkRoomEnv) and self.paid):
            # A step that ends on a cell and earns nothing rules the cell out, except in Dark Room Hard after the
            # episode has paid (it pays once), when the goal is found anyway.
            self.ruled_out[stage, cell] = True
        self.paid |= reward > 0
        if episode_end:
            self.paid = False


class PosteriorSearchDemonstrator:
    """Infers the hidden goal from its rewards (this module's docstring): in a room, a search (`search`, one of
    `SEARCHES`) for what its rewards have not shown yet, then straight to it; on a bandit, Thompson sampling."""

    def __init__(self, search: str = "sample") -> None:
        self.search = search
        self._rooms: list[_RoomSearch] = []
        self._arms: list[np.ndarray] = []
        """per bandit history: [arms, 2] successes and failures"""
        self._rngs: list[np.random.Generator] = []

    def begin(self, envs: Sequence[gym.Env], rngs: Sequence[np.random.Generator]) -> None:
        self._rngs = list(rngs)
        if self.search != "sample" and any(isinstance(env.unwrapped, BernoulliBanditEnv) for env in envs):
            raise ValueError(f"a {self.search} search walks a room's cells; on a bandit use posterior-sampling "
                             "(Thompson sampling)")
        self._rooms = [_RoomSearch.new(rng, self.search) for rng in rngs]
        self._arms = [np.zeros((_actions(env), 2)) for env in envs]

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        actions = []
        for i, env in enumerate(envs):
            inner = env.unwrapped
            if isinstance(inner, BernoulliBanditEnv):
                draws = self._rngs[i].beta(1 + self._arms[i][:, 0], 1 + self._arms[i][:, 1])
                actions.append(int(np.argmax(draws)))
            else:
                actions.append(self._rooms[i].move(_room(env)))
        return np.array(actions, dtype=np.int64)

    def observe(self, env_index: int, env: gym.Env, action: np.ndarray, reward: float, episode_end: bool) -> None:
        inner = env.unwrapped
        if isinstance(inner, BernoulliBanditEnv):
            self._arms[env_index][int(action), 0 if reward > 0 else 1] += 1
        else:
            self._rooms[env_index].observe(_room(env), int(action), reward, episode_end)

    def expert_act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        return _expert_actions(envs)


@dataclass(frozen=True)
class LearnerSettings:
    """AD's source algorithms as this package runs them."""

    learning_rate: float = 0.5
    """Q-learning's step size (the rooms are deterministic: a large step learns fast and stays right)"""
    discount: float = 0.9
    """Q-learning's discount"""
    exploration: float = 0.02
    """Q-learning's ε-greedy exploration (ties between equal values are broken at random too)"""
    initial_value: float = 1.0
    """Q-learning's initial values: optimistic (a reward is at most 1), so untried actions draw it on and it
    explores the room systematically. Measured on 20 goals each (normalized return at episodes 10 / 50 / 100):
    Dark Room 0.29 / 0.78 / 0.95, Key-to-Door 0.40 / 0.80 / 0.98, Dark Room Hard 0.35 / 0.60 / 1.00; with values
    starting at 0 and exploration 0.1, Dark Room reached 0.11 / 0.47 / 0.58"""
    ucb_c: float = 2.0 ** 0.5
    """UCB1's exploration constant"""


class LearnerDemonstrator:
    """AD's own histories: an RL algorithm learning from scratch on each history's env (tabular Q-learning in a
    room, UCB1 on a bandit; this module's docstring)."""

    def __init__(self, settings: LearnerSettings = LearnerSettings()) -> None:
        self.settings = settings
        self._q: list[np.ndarray] = []
        """per room history: Q-values [cells, paid (0/1), actions]"""
        self._paid: list[bool] = []
        self._last: list[tuple[int, int]] = []
        """per room history: the (cell, paid) state its last action was taken in"""
        self._arms: list[np.ndarray] = []
        """per bandit history: [arms, 2] pulls and summed reward"""
        self._rngs: list[np.random.Generator] = []

    def begin(self, envs: Sequence[gym.Env], rngs: Sequence[np.random.Generator]) -> None:
        self._rngs = list(rngs)
        actions = [_actions(env) for env in envs]
        self._q = [np.full((SIZE * SIZE, 2, n), self.settings.initial_value) for n in actions]
        self._paid = [False] * len(envs)
        self._last = [(0, 0)] * len(envs)
        self._arms = [np.zeros((n, 2)) for n in actions]

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        actions = []
        for i, env in enumerate(envs):
            inner, rng = env.unwrapped, self._rngs[i]
            if isinstance(inner, BernoulliBanditEnv):
                pulls, total = self._arms[i][:, 0], self._arms[i][:, 1]
                if (pulls == 0).any():  # UCB1 pulls every arm once first
                    actions.append(int(np.flatnonzero(pulls == 0)[0]))
                    continue
                bonus = self.settings.ucb_c * np.sqrt(np.log(pulls.sum()) / pulls)
                actions.append(int(np.argmax(total / pulls + bonus)))
                continue
            state = (_cell(_room(env).position), int(self._paid[i]))
            self._last[i] = state
            values = self._q[i][state[0], state[1]]
            if rng.random() < self.settings.exploration:
                actions.append(int(rng.integers(len(values))))
            else:
                actions.append(int(rng.choice(np.flatnonzero(values == values.max()))))
        return np.array(actions, dtype=np.int64)

    def observe(self, env_index: int, env: gym.Env, action: np.ndarray, reward: float, episode_end: bool) -> None:
        inner, i = env.unwrapped, env_index
        if isinstance(inner, BernoulliBanditEnv):
            self._arms[i][int(action)] += (1.0, reward)
            return
        paid = self._paid[i] or reward > 0
        q, (cell, was_paid) = self._q[i], self._last[i]
        following = 0.0 if episode_end else self.settings.discount * q[_cell(_room(env).position), int(paid)].max()
        taken = (cell, was_paid, int(action))
        q[taken] += self.settings.learning_rate * (reward + following - q[taken])
        self._paid[i] = paid and not episode_end

    def expert_act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        return _expert_actions(envs)


def icrl_demonstrator(behaviour: str) -> IcrlExpert | PosteriorSearchDemonstrator | LearnerDemonstrator:
    """The demonstrator of a discrete benchmark that plays as `behaviour` (one of `ICRL_BEHAVIOURS`)."""
    if behaviour in ("posterior-search", "walk-search"):
        return PosteriorSearchDemonstrator(search="spiral" if behaviour == "posterior-search" else "walk")
    return {"expert": IcrlExpert, "posterior-sampling": PosteriorSearchDemonstrator,
            "learner": LearnerDemonstrator}[behaviour]()
