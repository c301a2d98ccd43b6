"""Does success hold over many shots? Per task, success in shot ranges and each run's shots as a strip.

Reads the episodes.csv of `vintix eval` folders and prints, per task, the success rate of shot 1, of shots
2-10 and of each later block of 10 shots, and (with --strips) one line per run: `#` for a shot that
succeeded, `.` for one that did not. A model that holds its skill keeps its blocks level; one whose misses
are absorbing shows runs that succeed, miss once, and miss from then on.

    python scripts/success_over_shots.py RESULTS [RESULTS ...] [--strips]

The project's target (docs/in-context-rl.md): success over shots 31-40 at least success over shots 2-10
minus 0.05, on every hidden-goal task.
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from pathlib import Path

import numpy as np


def success_by_run(folder: Path) -> dict[str, dict[int, dict[int, float]]]:
    """task -> seed -> shot -> success, from a `vintix eval` folder's episodes.csv."""
    runs: dict[str, dict[int, dict[int, float]]] = defaultdict(lambda: defaultdict(dict))
    with (folder / "episodes.csv").open() as file:
        for row in csv.DictReader(file):
            runs[row["task"]][int(row["seed"])][int(row["shot"])] = float(row["success"])
    return runs


def shot_blocks(shots: int) -> list[tuple[int, int]]:
    """Shot 1, shots 2-10, then blocks of 10 (the last one cut at `shots`)."""
    blocks = [(1, 1), (2, min(10, shots))]
    blocks += [(start, min(start + 9, shots)) for start in range(11, shots + 1, 10)]
    return [(a, b) for a, b in blocks if a <= b]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", nargs="+", type=Path, help="folders `vintix eval --out` wrote")
    parser.add_argument("--strips", action="store_true", help="also print each run's shots as # and .")
    args = parser.parse_args()
    for folder in args.results:
        for task, runs in sorted(success_by_run(folder).items()):
            shots = max(max(run) for run in runs.values())
            rate = {block: np.mean([np.mean([run[s] for s in range(block[0], block[1] + 1) if s in run])
                                    for run in runs.values()]) for block in shot_blocks(shots)}
            cells = "  ".join(f"{a}-{b}: {r:.2f}" if a != b else f"{a}: {r:.2f}" for (a, b), r in rate.items())
            print(f"{folder}  {task}  ({len(runs)} runs)  {cells}")
            if args.strips:
                for seed, run in sorted(runs.items()):
                    print(f"  seed {seed:>6}  " + "".join("#" if run.get(s) else "." for s in range(1, shots + 1)))


if __name__ == "__main__":
    main()
