"""UCB1, DPT's UCB, Thompson sampling and a uniformly random policy on the bandits a model is evaluated on, scored as
`vintix eval` scores a model: per episode, the return over the run's optimal return, and the regret (optimal return −
return, summed over episodes). docs/discrete-tasks.md puts these beside the bandit models.

    python scripts/bandit_baselines.py [--seeds 16] [--first-seed 100] [--shots 40] [MODEL_RESULTS ...]

DPT's protocol (Lee et al., 2023: 500 pulls, 200 bandits): --seeds 200 --shots 50.

MODEL_RESULTS: `vintix eval` folders of BernoulliBandit-v0 to print beside the baselines (their episodes.csv).
"""

from __future__ import annotations

import argparse
import csv
from collections.abc import Sequence
from pathlib import Path

import gymnasium as gym
import numpy as np

from vintix.demonstrators.discrete_benchmarks import LearnerDemonstrator, PosteriorSearchDemonstrator
from vintix.demonstrators.posterior import GoalInferringDemonstrator
from vintix.tasks import make_env

TASK = "BernoulliBandit-v0"


class UniformRandom:
    """An arm pulled uniformly at random, with the collector's protocol of a demonstrator that reads rewards."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def begin(self, envs: Sequence[gym.Env], rngs: Sequence[np.random.Generator]) -> None:
        pass

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        return self.rng.integers(5, size=len(envs))

    def observe(self, env_index: int, env: gym.Env, action: np.ndarray, reward: float, episode_end: bool) -> None:
        pass

    def expert_act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        return np.zeros(len(envs), dtype=np.int64)


class DptUcb(LearnerDemonstrator):
    """UCB with DPT's bonus, 1/√n (its paper's UCB baseline), where UCB1's is √(2 ln t / n)."""

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        actions = []
        for pulls, total in ((arms[:, 0], arms[:, 1]) for arms in self._arms):
            untried = np.flatnonzero(pulls == 0)
            actions.append(int(untried[0]) if len(untried) else int(np.argmax(total / pulls + 1 / np.sqrt(pulls))))
        return np.array(actions, dtype=np.int64)


def play(policy: GoalInferringDemonstrator, seeds: list[int], shots: int) -> tuple[np.ndarray, np.ndarray]:
    """[runs, shots] returns and optimal returns of `policy` on the bandits of `seeds`, stepped together."""
    envs = [make_env(TASK, seed=s) for s in seeds]
    policy.begin(envs, [np.random.default_rng(s) for s in seeds])
    returns = np.zeros((len(envs), shots))
    optimal = np.array([env.unwrapped.optimal_return() for env in envs])
    observations = np.stack([env.reset()[0] for env in envs])
    for shot in range(shots):
        done = False
        while not done:
            actions = policy.act(observations, envs)
            for i, env in enumerate(envs):
                observations[i], reward, terminated, truncated, _ = env.step(int(actions[i]))
                policy.observe(i, env, actions[i], reward, terminated or truncated)
                returns[i, shot] += reward
                done = terminated or truncated
        observations = np.stack([env.reset()[0] for env in envs])
    return returns, np.repeat(optimal[:, None], shots, axis=1)


def from_results(folder: Path) -> tuple[np.ndarray, np.ndarray]:
    with (folder / "episodes.csv").open() as file:
        rows = [r for r in csv.DictReader(file) if r["task"] == TASK]
    seeds, shots = sorted({int(r["seed"]) for r in rows}), max(int(r["shot"]) for r in rows)
    returns, optimal = np.zeros((len(seeds), shots)), np.zeros((len(seeds), shots))
    for r in rows:
        i, k = seeds.index(int(r["seed"])), int(r["shot"]) - 1
        returns[i, k], optimal[i, k] = float(r["return"]), float(r["optimal"])
    return returns, optimal


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="*", type=Path)
    parser.add_argument("--seeds", type=int, default=16)
    parser.add_argument("--first-seed", type=int, default=100)
    parser.add_argument("--shots", type=int, default=40)
    args = parser.parse_args()
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    runs = {"UCB1": play(LearnerDemonstrator(), seeds, args.shots),
            "UCB, DPT's bonus": play(DptUcb(), seeds, args.shots),
            "Thompson sampling": play(PosteriorSearchDemonstrator(), seeds, args.shots),
            "uniform random": play(UniformRandom(0), seeds, args.shots)}
    runs |= {str(folder): from_results(folder) for folder in args.results}
    shown = [1, 2, 5, 10, 20, 40, 50]
    print(f"{TASK}, seeds {seeds[0]}-{seeds[-1]}: return / optimal at episodes {shown} (10 pulls each), "
          f"converged (best 10 episodes), regret after {args.shots} episodes ({10 * args.shots} pulls)")
    for name, (returns, optimal) in runs.items():
        score = (returns / optimal).mean(axis=0)
        converged = max(score[k:k + 10].mean() for k in range(len(score) - 9))
        regret = (optimal - returns).sum(axis=1)
        print(f"  {name}: " + " ".join(f"{score[k - 1]:.2f}" for k in shown if k <= len(score))
              + f"; converged {converged:.2f}; regret {regret.mean():.1f} ± {regret.std() / np.sqrt(len(regret)):.1f}")


if __name__ == "__main__":
    main()
