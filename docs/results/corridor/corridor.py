"""A newcomer's env, written from scratch: a 12-cell corridor with a treasure buried under one hidden cell.

The agent starts at cell 0 of every 25-step episode and moves left or right, or digs where it stands; each dig on
the treasure pays 1, so the sooner it gets there the more it earns. Which cell hides it is drawn from the env's seed
and kept for the env's life, and the observation is the position only, so only the rewards say where to dig.
Goals are held out by region: held-out envs (`corridor-heldout`) hide it in cells 5-6, training ones anywhere else
(1-4, 7-11), so the search walks past the held-out region in training, but never finds anything there.
"""

import gymnasium as gym
import numpy as np

CELLS, STEPS = 12, 25
LEFT, RIGHT, DIG = 0, 1, 2
HELD_OUT_CELLS = np.array([5, 6])
TRAIN_CELLS = np.setdiff1d(np.arange(1, CELLS), HELD_OUT_CELLS)


class CorridorEnv(gym.Env):
    observation_space = gym.spaces.Box(0.0, CELLS - 1.0, (1,), np.float32)
    action_space = gym.spaces.Discrete(3)

    def __init__(self, held_out=False):
        self.cells = HELD_OUT_CELLS if held_out else TRAIN_CELLS
        self.treasure, self.position = int(self.cells[0]), 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        if seed is not None:  # vintix seeds each env's first reset: the treasure for the env's whole life
            self.treasure = int(np.random.default_rng(seed).choice(self.cells))
        self.position = 0
        return np.array([self.position], np.float32), {}

    def step(self, action):
        action = int(action)
        if action != DIG:
            self.position = int(np.clip(self.position + (1 if action == RIGHT else -1), 0, CELLS - 1))
        found = action == DIG and self.position == self.treasure
        return np.array([self.position], np.float32), float(found), False, False, {"success": float(found)}

    def optimal_return(self):
        return float(STEPS - self.treasure)  # walk straight there, then dig every step left


def make_train(seed=None):
    return CorridorEnv()


def make_heldout(seed=None):
    return CorridorEnv(held_out=True)


class DigInTurn:
    """The newcomer's search: walk right digging each cell not yet dug in vain (remembered across episodes), and,
    once one paid, walk straight to it and dig."""

    def begin(self, envs, rngs):
        self.found = [None] * len(envs)
        self.next_cell = [1] * len(envs)  # cell 0 is never the treasure

    def _target(self, i):
        return self.found[i] if self.found[i] is not None else self.next_cell[i]

    def act(self, observations, envs):
        positions = observations[:, 0].astype(int)
        targets = np.array([self._target(i) for i in range(len(envs))])
        return np.where(positions < targets, RIGHT, np.where(positions > targets, LEFT, DIG))

    def observe(self, i, env, action, reward, episode_end):
        if int(action) != DIG:
            return
        if reward > 0:
            self.found[i] = env.unwrapped.position
        elif env.unwrapped.position == self.next_cell[i]:
            self.next_cell[i] = min(self.next_cell[i] + 1, CELLS - 1)

    def expert_act(self, observations, envs):
        positions = observations[:, 0].astype(int)
        targets = np.array([env.unwrapped.treasure for env in envs])
        return np.where(positions < targets, RIGHT, np.where(positions > targets, LEFT, DIG))


def make_demonstrator(task):
    return DigInTurn()
