"""The lowest cross-entropy a model can reach on DPT's bandit target (recipe bandit-dpt): the Bayes-optimal
posterior over which arm is best, after each prefix of a history of uniformly random pulls, scored against the
true best arm, averaged over the prefixes a 500-step training window holds. A trained model's loss far above it
is a learning failure, not a limit of the data. Monte Carlo: Beta(1, 1) posteriors per arm, `--draws` samples.

    python scripts/bandit_bayes_loss.py --bandits 200
"""

from __future__ import annotations

import argparse

import numpy as np


def bayes_cross_entropy(bandits: int, arms: int, pulls: int, draws: int, seed: int) -> np.ndarray:
    """Mean over `bandits` of -log P(true best arm | the first t pulls), for t = 0 .. pulls - 1."""
    rng = np.random.default_rng(seed)
    total = np.zeros(pulls)
    for _ in range(bandits):
        means = rng.uniform(size=arms)
        chosen = rng.integers(arms, size=pulls)
        rewards = rng.uniform(size=pulls) < means[chosen]
        wins, losses = np.zeros(arms), np.zeros(arms)
        for t in range(pulls):
            samples = rng.beta(1 + wins, 1 + losses, size=(draws, arms))
            best = np.bincount(samples.argmax(axis=1), minlength=arms) / draws
            total[t] -= np.log(max(best[means.argmax()], 1.0 / draws))
            wins[chosen[t]] += rewards[t]
            losses[chosen[t]] += 1 - rewards[t]
    return total / bandits


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bandits", type=int, default=200)
    parser.add_argument("--arms", type=int, default=5)
    parser.add_argument("--pulls", type=int, default=500)
    parser.add_argument("--draws", type=int, default=400)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    loss = bayes_cross_entropy(args.bandits, args.arms, args.pulls, args.draws, args.seed)
    print(f"Bayes-optimal cross-entropy, mean over the {args.pulls} prefixes: {loss.mean():.3f} "
          f"(prefix 0: {loss[0]:.3f}, 100: {loss[min(100, args.pulls - 1)]:.3f}, last: {loss[-1]:.3f}); "
          f"a uniform guess: {np.log(args.arms):.3f}")


if __name__ == "__main__":
    main()
