"""Is a model that fails in closed loop memorizing its histories, or imitating them well and failing anyway?

Computes a trained model's loss (the training objective, teacher-forced) per task on random windows of
one or more datasets: its own training data beside histories collected on goals it never saw (for
example `vintix collect --recipe R --seed 777 --out heldout` with fewer histories). Equal losses on both
say the model generalizes its imitation to new goals, so a closed-loop failure comes from what it does
with its own actions in context (compounding errors, contexts unlike its training ones); a much larger
loss on the new goals says it memorized the training histories.

    python scripts/window_loss.py CHECKPOINT DATA [DATA ...] [--windows 64] [--seed 123] [--by-position]

`--by-position` gives the loss at positions of the window instead (a window's first token sees nothing before it,
its last the whole window): a loss that stops falling after a few positions says the model uses only the latest
steps of its context, whatever the window holds.

The windows, targets and tasks are the checkpoint's training settings (`train_config` in its
config.json: window length, expert distillation, the tasks it was trained on).
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
import torch

from vintix.agent.pretrained import resolve_checkpoint
from vintix.model import Vintix
from vintix.model.checkpoint import load_pretrained, read_metadata
from vintix.train.data import WindowDataset, collate_windows, load_training_data
from vintix.train.trainer import WindowLoss

BATCH = 16
"""Windows per forward pass."""


def task_losses(model: Vintix, extra: dict[str, Any], root: str, windows: int, seed: int,
                by_position: bool = False) -> dict[str, np.ndarray]:
    """Per-window loss of `model`, whose checkpoint records `extra` (its tasks and training config), on
    about `windows` windows a task of the dataset at `root`; `by_position`: each window's loss per position."""
    config = extra["train_config"]
    data = load_training_data(root, tasks=extra["trained_tasks"], expert_distillation=config["expert_distillation"],
                              expert_tail_fraction=config["expert_tail_fraction"], expert_rows=config["expert_rows"])
    dataset = WindowDataset(data, config["window_len"] or model.config.context_len, seed=seed,
                            episode_returns=model.config.episode_return)
    module = WindowLoss(model)
    loss = module.per_position if by_position else module
    losses: dict[str, list[Any]] = {}
    with torch.no_grad():
        for start in range(0, windows * len(data.tasks), BATCH):
            # collate_windows stacks windows group by group (sorted by name): sorted so, the losses it
            # gives back are in the batch's order.
            batch = sorted((dataset[i] for i in range(start, start + BATCH)), key=lambda w: str(w["group"]))
            names = [data.tasks[int(w["task_idx"])].name for w in batch]
            for window, name in zip(batch, names, strict=True):  # the dataset's task order is not the model's
                window["task_idx"] = model.task_index(name)
            for name, value in zip(names, loss(collate_windows(batch)).tolist(), strict=True):
                losses.setdefault(name, []).append(value)
    return {name: np.asarray(values) for name, values in sorted(losses.items())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint", help="a checkpoint or training run folder")
    parser.add_argument("data", nargs="+", help="dataset roots (the training data, and data on new goals)")
    parser.add_argument("--windows", type=int, default=64,
                        help="windows drawn per task (about: each window's task is drawn at random)")
    parser.add_argument("--seed", type=int, default=123, help="which windows are drawn")
    parser.add_argument("--by-position", action="store_true", help="the mean loss at positions of the window")
    args = parser.parse_args()
    checkpoint = resolve_checkpoint(args.checkpoint)
    model, extra = load_pretrained(checkpoint).eval(), read_metadata(checkpoint)["extra"]
    print(f"{checkpoint}: mean loss per window ± standard error")
    for root in args.data:
        for task, values in task_losses(model, extra, root, args.windows, args.seed, args.by_position).items():
            if args.by_position:
                curve = values.mean(axis=0)
                marks = sorted({0, 1, 2, 5, 10, 20, 50, 100, 200, len(curve) - 1} & set(range(len(curve))))
                print(f"  {root}  {task:16s} " + ", ".join(f"position {p}: {curve[p]:.3f}" for p in marks))
                continue
            error = values.std(ddof=1) / np.sqrt(len(values)) if len(values) > 1 else float("nan")
            print(f"  {root}  {task:16s} {values.mean():.5f} ± {error:.5f}  ({len(values)} windows)")


if __name__ == "__main__":
    main()
