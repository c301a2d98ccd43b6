"""The discrete benchmarks in-context RL is measured on: Dark Room, Dark Room Hard, Key-to-Door, a Bernoulli bandit.

They are the home of Algorithm Distillation (Laskin et al., 2022), AD^ε (Zisman et al., 2024, whose noise
distillation Vintix extends) and DPT (Lee et al., 2023). Each hides what the agent must find (a goal cell, a key
and a door, the arms' means), draws it from the env's seed once (a room: goal ``seed mod`` the number of goals,
`pick`) and keeps it for the env's life, and never shows
it: only the rewards reveal it, so a model that ignores them cannot beat a goal-blind policy.

- **Dark Room** (``DarkRoom-v0``): a 9×9 grid, the agent starts at the centre (4, 4) every episode and observes
  its position ``(x, y)``; 5 actions (0 stay, 1 up, 2 down, 3 left, 4 right; a move into the wall stays);
  20-step episodes; reward 1 on every step that ends on the goal. 81 goals, split as AD^ε does: 65 train, 16
  test (its very cells, `AD_EPS_TEST_GOALS`). ``DarkRoom-v0`` draws its goal from the 65, ``DarkRoom-heldout-v0``
  from the 16 (a task of its own, so training data and held-out goals can never mix).
- **Dark Room Hard** (``DarkRoomHard-v0``, ``DarkRoomHard-heldout-v0``): the same room, reward 1 only the first
  time an episode reaches the goal. Ours: AD's Dark Room Hard is a 17×17 room with 289 goals, not comparable.
- **Key-to-Door** (``KeyToDoor-v0``, ``KeyToDoor-heldout-v0``): the same room and actions, a hidden key and a
  hidden door (distinct cells); reward 1 the first time the agent stands on the key, then 1 when it stands on the
  door holding it, which ends the episode; 50-step episodes. The observation is the position only: whether the key
  is held is in the context (its reward). Held-out pairs: a fixed fifth of the 81 × 80 (key, door) pairs.
  ``KeyToDoorRandomStart-v0`` (and ``-heldout-v0``): AD^ε's version, each episode starting on a random cell other
  than the key (AD's starts on a random cell too), so that no episode is a copy of the last.
- **Bernoulli bandit** (``BernoulliBandit-v0``): 5 arms whose success probabilities are drawn uniformly from [0, 1]
  by the seed; an episode is 10 pulls (so a token carries the previous pull's arm and reward) and the context
  carries over across episodes. The observation is a constant 0. New bandits: new seeds (the means are
  continuous, no two seeds share them).

The optimal return per goal (`optimal_return`) is each task's reference: scores are returns normalized by it,
and a random policy's mean return (`random_return`) is its floor.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

if TYPE_CHECKING:  # the registry imports this module to build its table
    from vintix.tasks.registry import TaskSpec

SIZE = 9
"""Cells per side of the room."""
START = (SIZE // 2, SIZE // 2)
MOVES = np.array([(0, 0), (0, 1), (0, -1), (-1, 0), (1, 0)])
"""Action i moves the agent by MOVES[i]: stay, up, down, left, right."""
DARK_ROOM_STEPS = 20
KEY_TO_DOOR_STEPS = 50
BANDIT_ARMS = 5
BANDIT_PULLS = 10
"""Pulls per bandit episode."""
SPLIT_SEED = 0
"""Seed of the fixed train/test split of (key, door) pairs (Key-to-Door)."""
HELD_OUT_PAIR_FRACTION = 0.2
AD_EPS_TEST_GOALS = ((7, 0), (7, 6), (4, 1), (3, 2), (0, 1), (5, 7), (2, 3), (0, 2), (2, 5), (8, 3), (8, 2), (2, 2),
                     (6, 6), (7, 8), (1, 5), (5, 6))
"""AD^ε's 16 test goals of Dark Room: the last 16 of the 81 cells permuted by ``np.random.permutation`` after
``np.random.seed(42)`` (corl-team/ad-eps, ``utils/misc.py::train_test_goals`` with ``eval_seed`` 42), as its
``(row, column)`` positions; ours read them as ``(x, y)``, the same cells of a room whose start is its centre."""


def cells() -> np.ndarray:
    """Every cell of the room ``[81, 2]``, row by row (x fastest)."""
    return np.array([(x, y) for y in range(SIZE) for x in range(SIZE)])


@cache
def goal_split() -> tuple[np.ndarray, np.ndarray]:
    """(train goals [65, 2], held-out goals [16, 2]): AD^ε's 65/16 split of the 81 cells (`AD_EPS_TEST_GOALS`)."""
    every = cells()
    held_out = np.array([tuple(c) in AD_EPS_TEST_GOALS for c in every])
    return every[~held_out], every[held_out]


@cache
def pair_split() -> tuple[np.ndarray, np.ndarray]:
    """(train, held-out) (key, door) pairs as cell indices ``[n, 2]``: every ordered pair of distinct cells, a fixed
    fifth of them held out."""
    n = SIZE * SIZE
    pairs = np.array([(k, d) for k in range(n) for d in range(n) if k != d])
    order = np.random.default_rng(SPLIT_SEED).permutation(len(pairs))
    held = int(len(pairs) * HELD_OUT_PAIR_FRACTION)
    return pairs[np.sort(order[held:])], pairs[np.sort(order[:held])]


def pick(seed: int | None, count: int) -> int:
    """Which of `count` goals (or pairs) an env of seed `seed` hides: ``seed mod count``, so that consecutive seeds
    play every held-out goal once (seeds 100-115: each of Dark Room's 16); a random one without a seed."""
    return int(np.random.default_rng().integers(count)) if seed is None else seed % count


def step_towards(position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The shortest-path action(s) from `position` to `target` (``[..., 2]`` each): along x first, then y, stay on
    it. Vectorized, so a batch of envs (or of candidate goals) takes one call."""
    dx, dy = target[..., 0] - position[..., 0], target[..., 1] - position[..., 1]
    return np.where(dx > 0, 4, np.where(dx < 0, 3, np.where(dy > 0, 1, np.where(dy < 0, 2, 0))))


def check_action(space: gym.spaces.Discrete, action: Any) -> int:
    """`action` as the index it is, or a ValueError naming the space."""
    if not space.contains(action):
        raise ValueError(f"action {action!r} is not in {space} (an integer 0-{int(space.n) - 1})")
    return int(action)


def distance(a: np.ndarray | tuple[int, int], b: np.ndarray | tuple[int, int]) -> np.ndarray:
    """Steps between cells (Manhattan distance: moves are along the axes)."""
    return np.abs(np.asarray(a) - np.asarray(b)).sum(axis=-1)


class GridEnv(gym.Env):
    """The room the grid tasks share: position, moves, the step counter; subclasses hide and pay."""

    metadata = {"render_modes": []}
    episode_steps = DARK_ROOM_STEPS

    action_space: gym.spaces.Discrete

    def __init__(self, seed: int | None = None, held_out: bool = False) -> None:
        self.observation_space = gym.spaces.Box(0.0, SIZE - 1.0, shape=(2,), dtype=np.float32)
        self.action_space = gym.spaces.Discrete(len(MOVES))
        self.held_out = held_out
        self._position = np.array(START)
        self._steps = 0
        self._draw(seed)

    def _draw(self, seed: int | None) -> None:
        raise NotImplementedError

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """`seed` draws the hidden goal anew, exactly as a new env with that seed would; otherwise it stays."""
        super().reset(seed=seed)
        if seed is not None:
            self._draw(seed)
        self._position, self._steps = np.array(START), 0
        self._begin_episode()
        return self._observation(), {}

    def _begin_episode(self) -> None:
        pass

    def _observation(self) -> np.ndarray:
        return self._position.astype(np.float32)

    def _move(self, action: Any) -> None:
        self._position = np.clip(self._position + MOVES[check_action(self.action_space, action)], 0, SIZE - 1)
        self._steps += 1

    @property
    def position(self) -> np.ndarray:
        """The agent's cell. For demonstrators (it is also the observation)."""
        return self._position.copy()


class DarkRoomEnv(GridEnv):
    """Dark Room: find the hidden goal cell and stay on it (reward 1 per step on it), or, `hard`, reach it once."""

    def __init__(self, seed: int | None = None, held_out: bool = False, hard: bool = False) -> None:
        self.hard = hard
        self._paid = False
        super().__init__(seed, held_out)

    def _draw(self, seed: int | None) -> None:
        goals = goal_split()[1 if self.held_out else 0]
        self._goal = goals[pick(seed, len(goals))]

    def _begin_episode(self) -> None:
        self._paid = False

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        self._move(action)
        on_goal = bool((self._position == self._goal).all())
        reward = float(on_goal and not (self.hard and self._paid))
        self._paid |= on_goal
        return self._observation(), reward, False, self._steps >= self.episode_steps, {"success": float(self._paid)}

    @property
    def true_goal(self) -> np.ndarray:
        """The hidden goal cell. For demonstrators only."""
        return self._goal.copy()

    def expert_action(self) -> int:
        """The goal-aware expert: the shortest path to the goal, then stay."""
        return int(step_towards(self._position, self._goal))

    def optimal_return(self) -> float:
        """The most an episode can earn under this env's goal."""
        steps = int(distance(START, self._goal))
        return 1.0 if self.hard else float(min(self.episode_steps, self.episode_steps - steps + 1))


class KeyToDoorEnv(GridEnv):
    """Key-to-Door: reward 1 on reaching the hidden key, then 1 on reaching the hidden door with it (the end).
    `random_start`: each episode starts on a cell drawn anew (never the key), as AD^ε's ``DarkKey2Door`` does,
    instead of the centre."""

    episode_steps = KEY_TO_DOOR_STEPS

    def __init__(self, seed: int | None = None, held_out: bool = False, random_start: bool = False) -> None:
        self._has_key = False
        self.random_start = random_start
        super().__init__(seed, held_out)

    def _draw(self, seed: int | None) -> None:
        pairs = pair_split()[1 if self.held_out else 0]
        key, door = pairs[pick(seed, len(pairs))]
        self._key, self._door = cells()[key], cells()[door]
        self._start_cells = np.delete(cells(), key, axis=0)  # a random start is anywhere but the key
        self._starts = np.random.default_rng(seed)  # the seed's own stream of starts, as a new env would draw

    def _begin_episode(self) -> None:
        self._has_key = False
        if self.random_start:
            self._position = self._start_cells[self._starts.integers(len(self._start_cells))]

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        self._move(action)
        reward = 0.0
        if not self._has_key and (self._position == self._key).all():
            self._has_key, reward = True, 1.0
        opened = self._has_key and bool((self._position == self._door).all())
        reward += float(opened)
        truncated = not opened and self._steps >= self.episode_steps
        return self._observation(), reward, opened, truncated, {"success": float(opened)}

    @property
    def true_goal(self) -> np.ndarray:
        """The hidden key and door cells ``[2, 2]``. For demonstrators only."""
        return np.stack([self._key, self._door])

    @property
    def has_key(self) -> bool:
        """Whether the agent holds the key this episode. For demonstrators only."""
        return self._has_key

    def expert_action(self) -> int:
        """The goal-aware expert: to the key, then to the door."""
        return int(step_towards(self._position, self._door if self._has_key else self._key))

    def optimal_return(self) -> float:
        return 2.0


class BernoulliBanditEnv(gym.Env):
    """A Bernoulli bandit: arm i pays 1 with probability ``means[i]`` (hidden, drawn from the seed)."""

    metadata = {"render_modes": []}
    action_space: gym.spaces.Discrete

    def __init__(self, seed: int | None = None, arms: int = BANDIT_ARMS, pulls: int = BANDIT_PULLS) -> None:
        self.observation_space = gym.spaces.Box(0.0, 1.0, shape=(1,), dtype=np.float32)  # always 0
        self.action_space = gym.spaces.Discrete(arms)
        self.pulls = pulls
        self._steps = 0
        self._means = np.zeros(arms)
        self._draw(seed)

    def _draw(self, seed: int | None) -> None:
        rng = np.random.default_rng(seed)
        self._means = rng.uniform(0.0, 1.0, int(self.action_space.n))
        self._payouts = np.random.default_rng(rng.integers(2**63))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """`seed` draws new means (and payout stream), as a new env with that seed would; otherwise they stay."""
        super().reset(seed=seed)
        if seed is not None:
            self._draw(seed)
        self._steps = 0
        return np.zeros(1, np.float32), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        arm = check_action(self.action_space, action)
        self._steps += 1
        reward = float(self._payouts.random() < self._means[arm])
        # No success flag: a bandit is scored by its return against the best arm's (and its regret).
        return np.zeros(1, np.float32), reward, False, self._steps >= self.pulls, {}

    @property
    def true_goal(self) -> np.ndarray:
        """The arms' means. For demonstrators only."""
        return self._means.copy()

    def expert_action(self) -> int:
        """The goal-aware expert: the best arm."""
        return int(np.argmax(self._means))

    def optimal_return(self) -> float:
        """An episode's expected return pulling the best arm."""
        return float(self.pulls * self._means.max())


@dataclass(frozen=True)
class IcrlTask:
    """One task of the domain: its name, env, episode length and observation."""

    name: str
    group: str
    obs_dim: int
    actions: int
    episode_length: int
    kwargs: dict[str, Any]
    split: str = "train"


def _grid_tasks() -> list[IcrlTask]:
    tasks = []
    for name, env, steps, extra in (("DarkRoom", "dark_room", DARK_ROOM_STEPS, {}),
                                    ("DarkRoomHard", "dark_room", DARK_ROOM_STEPS, {"hard": True}),
                                    ("KeyToDoor", "key_to_door", KEY_TO_DOOR_STEPS, {}),
                                    ("KeyToDoorRandomStart", "key_to_door", KEY_TO_DOOR_STEPS, {"random_start": True})):
        for held_out in (False, True):
            tasks.append(IcrlTask(f"{name}{'-heldout' if held_out else ''}-v0", name.lower(), 2, len(MOVES), steps,
                                  {"env": env, "held_out": held_out, **extra}, "test" if held_out else "train"))
    return tasks


@cache
def icrl_tasks() -> dict[str, IcrlTask]:
    """The domain's tasks by name. Each grid task is its own group: the same observation means another thing
    in Dark Room (where the goal is) and Key-to-Door (the key, then the door)."""
    bandit = IcrlTask("BernoulliBandit-v0", "bernoulli-bandit", 1, BANDIT_ARMS, BANDIT_PULLS, {"env": "bandit"})
    return {task.name: task for task in [*_grid_tasks(), bandit]}


def icrl_task_specs() -> list[TaskSpec]:
    """The registry's specs of the domain's tasks (no published scores: `vintix.tasks.scores` gives their
    references, the optimal return and a random policy's)."""
    from vintix.tasks.registry import TaskSpec

    return [TaskSpec(name=t.name, domain="icrl", group=t.group, obs_dim=t.obs_dim, act_dim=t.actions,
                     episode_length=t.episode_length, reward_scale=1.0, split=t.split,  # type: ignore[arg-type]
                     aliases=(), paper_random=None, paper_expert=None, paper_vintix_normalized=None,
                     paper_history_length=0, paper_histories=0, action_type="discrete")
            for t in icrl_tasks().values()]


def icrl_env(name: str, seed: int | None = None) -> gym.Env:
    """The env of task `name` with its hidden goal drawn from `seed` (gymnasium's entry point for ``vintix/<name>``,
    which adds the time limit)."""
    options = dict(icrl_tasks()[name].kwargs)
    kind = options.pop("env")
    env: gym.Env = {"dark_room": DarkRoomEnv, "key_to_door": KeyToDoorEnv, "bandit": BernoulliBanditEnv}[kind](
        seed, **options)
    return env
