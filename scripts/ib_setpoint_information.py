"""How much Industrial Benchmark's setpoint decides: would hiding it make a task that needs rewards?

The shipped PPO demonstrator serves every setpoint, reading it from observation[0]. Fed a fixed setpoint q
in place of the true one, it is a policy that does not know the setpoint; the best such q over all
setpoints is the best setpoint-blind policy of that family. The hidden information is the setpoint-aware
demonstrator's mean normalized score (ours) minus that policy's. Any setpoint-blind policy the family misses
could only score higher, so the number is an upper bound.

    python scripts/ib_setpoint_information.py [--episodes 5] [--first-seed 100]

Measured 2026-12-05 (5 episodes per cell, env seeds 100-104, setpoints 0, 10, ..., 100): the setpoint-aware
demonstrator 0.988, the best blind one (fed q = 10) 0.792, hidden information 0.195: below 0.2, so no
hidden-setpoint task is registered (docs/tasks.md).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import gymnasium as gym
import numpy as np

from vintix.demonstrators import load_demonstrator
from vintix.demonstrators.base import Demonstrator
from vintix.demonstrators.scores import episode_returns
from vintix.tasks.scores import reference

SETPOINTS = tuple(range(0, 101, 10))


class FixedSetpoint:
    """The demonstrator fed setpoint `setpoint` whatever the env's is (None: the env's own)."""

    def __init__(self, expert: Demonstrator, setpoint: float | None) -> None:
        self.expert, self.setpoint = expert, setpoint

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        fed = np.array(observations, copy=True)
        if self.setpoint is not None:
            fed[:, 0] = self.setpoint
        return self.expert.act(fed, envs)


def normalized_scores(episodes: int, first_seed: int) -> dict[int, dict[int | None, float]]:
    """Per true setpoint, the mean normalized score (ours) fed each setpoint of `SETPOINTS` (None: its own)."""
    table: dict[int, dict[int | None, float]] = {}
    for setpoint in SETPOINTS:
        task = f"industrial-benchmark-{setpoint}-v1"
        expert, scale = load_demonstrator(task), reference(task, "ours")
        assert scale is not None, f"{task} has no reference in the package's score table"
        table[setpoint] = {fed: float(scale.normalize(episode_returns(task, FixedSetpoint(expert, fed), episodes,
                                                                      first_seed).mean()))
                           for fed in (None, *SETPOINTS)}
        print(f"setpoint {setpoint:3d}: own {table[setpoint][None]:.2f}; fed "
              + " ".join(f"{fed}: {table[setpoint][fed]:.2f}" for fed in SETPOINTS), flush=True)
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=5, help="episodes per (setpoint, fed setpoint)")
    parser.add_argument("--first-seed", type=int, default=100)
    args = parser.parse_args()
    table = normalized_scores(args.episodes, args.first_seed)
    aware = np.mean([row[None] for row in table.values()])
    blind = {fed: np.mean([row[fed] for row in table.values()]) for fed in SETPOINTS}
    best = max(blind, key=lambda fed: blind[fed])
    print(f"setpoint-aware {aware:.3f}; best setpoint-blind (fed {best}) {blind[best]:.3f}; "
          f"hidden information {aware - blind[best]:.3f}")


if __name__ == "__main__":
    main()
