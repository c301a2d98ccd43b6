"""``vintix bench train``: training tokens/s and MFU of the model presets on this machine.

MFU is relative to this device's own dense matmul rate measured in the same run (fp32 on CPU,
bf16 on CUDA), so the number says how much of the hardware the training step uses, not how the
machine compares with a datasheet. The step is the trainer's own (`WindowLoss`, `build_optimizer`,
`precision_context`) on synthetic windows of one Meta-World-sized group: data loading is left out
on purpose, it runs in DataLoader workers during training.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import torch

from vintix.model.model import GroupSpec, TaskNorm, Vintix, count_parameters, preset
from vintix.tasks import list_tasks
from vintix.train.config import TrainConfig
from vintix.train.trainer import (
    WindowLoss,
    build_optimizer,
    flops_per_token,
    measure_matmul_flops,
    precision_context,
)


@dataclass
class TrainBenchmark:
    """One preset's measured training speed."""

    preset: str
    parameters: int
    """parameters with one encoder/head per group of the whole task registry (the paper's layout)"""
    batch_size: int
    window_len: int
    tokens_per_s: float
    mfu: float


def registry_groups() -> list[GroupSpec]:
    """One GroupSpec per group of the task registry (all 102 tasks)."""
    groups: dict[str, GroupSpec] = {}
    for task in list_tasks():
        groups.setdefault(task.group, GroupSpec(task.group, task.obs_dim, task.act_dim))
    return list(groups.values())


def parameter_count(preset_name: str) -> int:
    """Parameters of a preset with every registry group, counted on the meta device (no memory used)."""
    groups = registry_groups()
    norms = [TaskNorm(g.name, g.name, [0.0] * g.obs_dim, [1.0] * g.obs_dim) for g in groups]
    with torch.device("meta"):
        return count_parameters(Vintix(preset(preset_name), groups, norms))


def _synthetic_batch(group: GroupSpec, batch_size: int, window_len: int, device: torch.device) -> dict:
    step_num = torch.arange(window_len).remainder(100).expand(batch_size, -1)  # 100-step episodes
    return {group.name: {
        "task_idx": torch.zeros(batch_size, dtype=torch.long),
        "obs": torch.randn(batch_size, window_len, group.obs_dim),
        "prev_action": torch.rand(batch_size, window_len, group.act_dim) * 2 - 1,
        "prev_reward": torch.rand(batch_size, window_len),
        "step_num": step_num.contiguous(),
        "action": torch.rand(batch_size, window_len, group.act_dim) * 2 - 1,
    }}


def benchmark_preset(name: str, peak_flops: float, batch_size: int, steps: int, device: torch.device) -> TrainBenchmark:
    """Time ``steps`` full training steps (forward, backward, AdamW) after one warm-up step."""
    group = GroupSpec("metaworld", 39, 4)
    config = preset(name)
    torch.manual_seed(0)
    model = Vintix(config, [group], [TaskNorm("reach-v3", "metaworld", [0.0] * 39, [1.0] * 39)]).to(device)
    loss_module = WindowLoss(model)
    optimizer, _ = build_optimizer(model, TrainConfig(model=name))
    batch = {g: {k: v.to(device) for k, v in b.items()}
             for g, b in _synthetic_batch(group, batch_size, config.context_len, device).items()}

    def step() -> None:
        with precision_context(device):
            loss = loss_module(batch).mean()
        loss.backward()
        optimizer.step()
        optimizer.zero_grad(set_to_none=True)

    step()
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    start = time.perf_counter()
    for _ in range(steps):
        step()
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    tokens_per_s = steps * batch_size * config.context_len / (time.perf_counter() - start)
    mfu = tokens_per_s * flops_per_token(model, group.name, config.context_len) / peak_flops
    return TrainBenchmark(name, parameter_count(name), batch_size, config.context_len, tokens_per_s, mfu)


def benchmark_training(presets: list[str], batch_size: int, steps: int,
                       device: torch.device) -> tuple[float, list[TrainBenchmark]]:
    """The device's matmul peak (FLOP/s) and each preset's training speed."""
    dtype = torch.bfloat16 if device.type == "cuda" else torch.float32
    peak = measure_matmul_flops(device, dtype, size=2048)
    return peak, [benchmark_preset(name, peak, batch_size, steps, device) for name in presets]
