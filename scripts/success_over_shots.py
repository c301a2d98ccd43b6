"""Does success hold over many shots? Per task, success in shot ranges and each run's shots as a strip.

Reads the episodes.csv of `vintix eval` folders and prints, per task, the success rate of shot 1, of shots
2-10 and of each later block of 10 shots, and (with --strips) one line per run: `#` for a shot that
succeeded, `.` for one that did not. A model that holds its skill keeps its blocks level; one whose misses
are absorbing shows runs that succeed, miss once, and miss from then on. With --drift D it also prints the
mean return of the same blocks and how many runs' last block returns less (and more) than their shots
2-10 by over D: a run that drifts loses a little return every shot before its success flag shows it.

    python scripts/success_over_shots.py RESULTS [RESULTS ...] [--strips] [--drift 0.5]

The project's target (docs/in-context-rl.md): success over shots 31-40 at least success over shots 2-10
minus 0.05, on every hidden-goal task.
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from pathlib import Path

import numpy as np

Runs = dict[int, dict[int, float]]
"""seed -> shot -> a value of that episode"""


def episodes_by_run(folder: Path) -> dict[str, dict[str, Runs]]:
    """'success' and 'return' -> task -> seed -> shot -> value, from a `vintix eval` folder's episodes.csv."""
    columns: dict[str, dict[str, Runs]] = {column: defaultdict(lambda: defaultdict(dict))
                                           for column in ("success", "return")}
    with (folder / "episodes.csv").open() as file:
        for row in csv.DictReader(file):
            for column, runs in columns.items():
                runs[row["task"]][int(row["seed"])][int(row["shot"])] = float(row[column])
    return columns


def shot_blocks(shots: int) -> list[tuple[int, int]]:
    """Shot 1, shots 2-10, then blocks of 10 (the last one cut at `shots`)."""
    blocks = [(1, 1), (2, min(10, shots))]
    blocks += [(start, min(start + 9, shots)) for start in range(11, shots + 1, 10)]
    return [(a, b) for a, b in blocks if a <= b]


def block_means(run: dict[int, float], blocks: list[tuple[int, int]]) -> np.ndarray:
    """The run's mean over each block of shots."""
    return np.array([np.mean([run[s] for s in range(a, b + 1) if s in run]) for a, b in blocks])


def format_blocks(blocks: list[tuple[int, int]], values: np.ndarray) -> str:
    """``1: 0.15  2-10: 1.00  ...``"""
    cells = (f"{a}-{b}: {v:.2f}" if a != b else f"{a}: {v:.2f}" for (a, b), v in zip(blocks, values, strict=True))
    return "  ".join(cells)


def drift_line(runs: Runs, blocks: list[tuple[int, int]], threshold: float) -> str:
    """Mean return per block, and the runs whose last block returns over `threshold` less (more) than 2-10."""
    returns = np.array([block_means(run, blocks) for run in runs.values()])
    change = returns[:, -1] - returns[:, 1]
    return (f"  return  {format_blocks(blocks, returns.mean(axis=0))}  runs whose last block returns over "
            f"{threshold} less than shots 2-10: {(change < -threshold).sum()}, more: {(change > threshold).sum()}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", nargs="+", type=Path, help="folders `vintix eval --out` wrote")
    parser.add_argument("--strips", action="store_true", help="also print each run's shots as # and .")
    parser.add_argument("--drift", type=float, metavar="D",
                        help="also print mean return per block and the runs whose last block returns over D "
                             "less (more) than shots 2-10")
    args = parser.parse_args()
    for folder in args.results:
        episodes = episodes_by_run(folder)
        for task, runs in sorted(episodes["success"].items()):
            shots = max(max(run) for run in runs.values())
            blocks = shot_blocks(shots)
            rate = np.mean([block_means(run, blocks) for run in runs.values()], axis=0)
            print(f"{folder}  {task}  ({len(runs)} runs)  {format_blocks(blocks, rate)}")
            if args.drift is not None:
                print(drift_line(episodes["return"][task], blocks, args.drift))
            if args.strips:
                for seed, run in sorted(runs.items()):
                    print(f"  seed {seed:>6}  " + "".join("#" if run.get(s) else "." for s in range(1, shots + 1)))


if __name__ == "__main__":
    main()
