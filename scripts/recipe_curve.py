"""The learning curve of a demonstrator recipe with some of its fields changed, or of another task's recipe.

    OMP_NUM_THREADS=1 python scripts/recipe_curve.py --task Humanoid-v5 --set observation_dims=270 \
        --set stop_at_score=Infinity --steps 170000 --out runs/humanoid-270
    OMP_NUM_THREADS=1 python scripts/recipe_curve.py --task Humanoid-v5 --recipe-of HumanoidStandup-v5 \
        --out runs/humanoid-ppo
    OMP_NUM_THREADS=1 python scripts/recipe_curve.py --task Humanoid-v5 --set 'algorithm="TQC"' \
        --set timesteps=1000000 --set stop_at_score=Infinity --out runs/humanoid-tqc

Trains the task's recipe (`vintix demonstrator train`'s), or `--recipe-of` another task's, with each
`--set FIELD=JSON` of `DemonstratorRecipe` replaced, printing the mean return of the last 100 training
episodes every `--every` steps and, every 2.5 % of the recipe's budget, the deterministic score check of
`stop_at_score` (`Infinity`: check, never stop). `--steps` interrupts the run there, saved: re-run to
resume. The run lives under `--out`, apart from the recipe's own run, and writes its weights there when
it ends. The Humanoid comparison in docs/demonstrators.md comes from these callbacks (first run from an ad-hoc copy).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CallbackList

from vintix.demonstrators.trained import ALGORITHMS
from vintix.demonstrators.training import TrainingInterrupted, recipe_for, train_demonstrator


class PrintTrainingReturn(BaseCallback):
    """Prints the mean return of the last 100 training episodes each time training passes a multiple of
    `every` env steps (several envs step it by more than one)."""

    def __init__(self, every: int):
        super().__init__()
        self.every = every

    def _on_training_start(self) -> None:
        self.printed = self.model.num_timesteps // self.every

    def _on_step(self) -> bool:
        if self.num_timesteps // self.every != self.printed and self.model.ep_info_buffer:
            self.printed = self.num_timesteps // self.every
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


def parse_field(assignment: str) -> tuple[str, object]:
    """`FIELD=JSON` as (field, value): `observation_dims=270`, `stop_at_score=Infinity`."""
    name, _, value = assignment.partition("=")
    return name, json.loads(value)


def register_contrib_algorithms() -> None:
    """Lets `--set algorithm="TQC"` or `"CrossQ"` train sb3-contrib's, when it is installed beside vintix
    (`pip install sb3-contrib`; not a vintix dependency, so nothing shipped can need it)."""
    if importlib.util.find_spec("sb3_contrib") is not None:
        import sb3_contrib

        ALGORITHMS.update(TQC=sb3_contrib.TQC, CrossQ=sb3_contrib.CrossQ)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", required=True)
    parser.add_argument("--recipe-of", help="train with this task's recipe (default: --task's)")
    parser.add_argument("--set", type=parse_field, action="append", default=[], metavar="FIELD=JSON",
                        help="replace a DemonstratorRecipe field; repeat for several")
    parser.add_argument("--steps", type=int, help="stop (saved) after this many env steps (the budget stays)")
    parser.add_argument("--every", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    register_contrib_algorithms()
    recipe = replace(recipe_for(args.recipe_of or args.task), **dict(args.set))
    if recipe.algorithm not in ALGORITHMS:
        parser.error(f"unknown algorithm {recipe.algorithm!r}: one of {', '.join(ALGORITHMS)} "
                     "(TQC and CrossQ need `pip install sb3-contrib`)")
    callbacks = [PrintTrainingReturn(args.every)] + ([StopAt(args.steps)] if args.steps else [])
    try:
        path = train_demonstrator(args.task, seed=args.seed, out=args.out / "weights", recipe=recipe,
                                  state_dir=args.out / "state", progress_bar=False,
                                  report=lambda line: print(line, flush=True), callback=CallbackList(callbacks))
    except TrainingInterrupted as interrupted:
        print(interrupted)
    else:
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
