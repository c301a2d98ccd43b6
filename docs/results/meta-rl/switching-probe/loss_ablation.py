"""HalfCheetah-Vel with the switching probe (commit ad013f6): does the model's action on its own training histories
depend on their rewards? MSE against the target over steps 220-400 (after the probe) of 48 whole-history windows,
with their rewards, zeros, or another history's.

    python switching-probe/loss_ablation.py WORK/runs/ad/checkpoints/best WORK/data
"""

import sys

import torch

from vintix.model.checkpoint import load_pretrained
from vintix.train.data import WindowDataset, collate_windows, load_training_data

model = load_pretrained(sys.argv[1])
data = load_training_data(sys.argv[2], tasks=["HalfCheetah-Vel-v5"], expert_distillation=True, normalize_rewards=True)
task = data.tasks[0]
windows = WindowDataset(data, model.config.context_len, seed=123)
batch = collate_windows([windows[i] for i in range(48)])[task.group]
batch["task_idx"][:] = model.task_index(task.name)
rewards = batch["prev_reward"]
for name, fed in (("their rewards", rewards), ("zeros", torch.zeros_like(rewards)),
                  ("another history's", rewards.roll(1, dims=0))):
    with torch.no_grad():
        tokens = model.embed(task.group, batch["task_idx"], batch["obs"], batch["prev_action"], fed, batch["step_num"])
        mean, _ = model.action_distribution(task.group, model.backbone(tokens))
    print(f"{name}: {((mean - batch['action']) ** 2)[:, 220:400].mean():.4f}")
