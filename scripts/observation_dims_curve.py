"""The learning curve of a demonstrator recipe with its policy seeing only the first N observation dims.

    OMP_NUM_THREADS=1 python scripts/observation_dims_curve.py --task Humanoid-v5 --observation-dims 270 \
        --steps 170000 --out runs/humanoid-270

Trains the task's recipe (`vintix demonstrator train`'s) with `observation_dims` replaced, printing the
mean return of the last 100 training episodes every `--every` steps and, every 2.5 % of the recipe's
budget, the deterministic score check of `DemonstratorRecipe.stop_at_score` (a very high target, so it
never stops). `--observation-dims 0` is the control arm (all dims). Interrupt and re-run to resume; the
run lives under `--out`, apart from the recipe's own run. The README's Humanoid comparison comes from
these callbacks (first run from an ad-hoc copy of them).
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CallbackList

from vintix.demonstrators.training import TrainingInterrupted, recipe_for, train_demonstrator


class PrintTrainingReturn(BaseCallback):
    """Prints the mean return of the last 100 training episodes every `every` env steps."""

    def __init__(self, every: int):
        super().__init__()
        self.every = every

    def _on_step(self) -> bool:
        if self.num_timesteps % self.every == 0 and self.model.ep_info_buffer:
            mean = np.mean([episode["r"] for episode in self.model.ep_info_buffer])
            print(f"step {self.num_timesteps:,}: training return {mean:,.1f}", flush=True)
        return True


class StopAt(BaseCallback):
    """Interrupts (so the run is saved and resumable) after `steps` env steps."""

    def __init__(self, steps: int):
        super().__init__()
        self.steps = steps

    def _on_step(self) -> bool:
        if self.num_timesteps >= self.steps:
            raise KeyboardInterrupt
        return True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", required=True)
    parser.add_argument("--observation-dims", type=int, required=True, help="0: all of them")
    parser.add_argument("--steps", type=int, required=True, help="env steps to train (the recipe's budget stays)")
    parser.add_argument("--every", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    recipe = recipe_for(args.task)
    recipe = replace(recipe, observation_dims=args.observation_dims, stop_at_score=float("inf"))
    try:
        train_demonstrator(args.task, seed=args.seed, out=args.out / "weights", recipe=recipe,
                           state_dir=args.out / "state", progress_bar=False, report=lambda line: print(line, flush=True),
                           callback=CallbackList([PrintTrainingReturn(args.every), StopAt(args.steps)]))
    except TrainingInterrupted as interrupted:
        print(interrupted)


if __name__ == "__main__":
    main()
