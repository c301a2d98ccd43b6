"""`vintix bench infer`: per-step latency and throughput of the agent, KV cache vs full recompute.

Measured per preset and batch size, with the window full:
- *first full*: the step whose token fills the window (timed repeatedly from that state);
- *steady*: steps after the window has been full for 3× its length (positions 4W−1 onwards), the
  state a long run reaches; a cost that grew with run length, or a whole-cache copy per step, would
  show up here;
- *recompute*: one forward over the whole window (embed, backbone, head of the last token), what an
  agent without a cache (or the official one, which re-encodes the window) pays per step.
The cache states are set directly (positions and length) rather than reached by stepping: at the
paper's window of 8192 that would be 32k steps. Keys and values hold random numbers, since the
cost does not depend on them. `literal_steady_state` checks the shortcut on a short real run.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np
import torch

from vintix.agent.agent import Agent
from vintix.agent.cache import KVCache
from vintix.model.model import GroupSpec, ModelConfig, TaskNorm, Vintix, count_parameters, preset

GROUP = GroupSpec("metaworld", obs_dim=39, act_dim=4)
TASK = "reach-v3"


@dataclass
class InferenceTiming:
    """One (preset, batch) measurement; latencies are medians in milliseconds per agent step."""

    preset: str
    parameters: int
    window: int
    envs: int
    first_full_ms: float
    steady_ms: float
    recompute_ms: float | None
    """None where one full-window forward does not fit this machine's memory or time"""

    @property
    def steady_over_first_full(self) -> float:
        return self.steady_ms / self.first_full_ms

    @property
    def cache_speedup(self) -> float | None:
        return None if self.recompute_ms is None else self.recompute_ms / self.steady_ms

    @property
    def env_steps_per_second(self) -> float:
        return self.envs * 1000.0 / self.steady_ms


def bench_config(preset_name: str, window: int | None = None) -> ModelConfig:
    """`preset_name`'s config, with its context shortened (or lengthened) to `window` steps if given."""
    return preset(preset_name) if window is None else preset(preset_name, context_len=window)


def memory_needed(preset_name: str, envs: int, window: int | None = None) -> tuple[int, int]:
    """Bytes of the KV cache, and of a full-window recompute's largest buffers (the ALiBi bias shared
    across layers, fp32 [H, W, W], and the MLP activations [envs, W, mlp_dim] with a few copies)."""
    config = bench_config(preset_name, window)
    window, d = config.context_len, config.d_model
    cache = 2 * config.n_layers * envs * window * d * 4
    recompute = config.n_heads * window * window * 4 + 4 * envs * window * config.mlp_dim * 4
    return cache, recompute


def bench_model(preset_name: str, window: int | None = None) -> Vintix:
    """A randomly initialized model of `preset_name` (context `window`, if given) with one Meta-World-shaped
    group, fp32, eval."""
    torch.manual_seed(0)
    norm = TaskNorm(TASK, GROUP.name, [0.0] * GROUP.obs_dim, [1.0] * GROUP.obs_dim)
    return Vintix(bench_config(preset_name, window), [GROUP], [norm]).eval()


def set_cache_state(cache: KVCache, length: int) -> None:
    """Put `cache` in the state it has after `length` steps (which slot holds which position)."""
    filled = min(length, cache.window)
    positions = torch.arange(length - filled, length)
    cache.positions[:, positions % cache.window] = positions
    cache.length = length
    cache.clocks[:] = length


def _median_ms(step: Callable[[], object], repeats: int, before_each: Callable[[], None] = lambda: None) -> float:
    times = []
    for _ in range(repeats):
        before_each()
        start = time.perf_counter()
        step()
        times.append((time.perf_counter() - start) * 1000.0)
    return statistics.median(times)


def _agent(model: Vintix, envs: int) -> tuple[Agent, Callable[[], object]]:
    agent = Agent(model)
    agent.reset([TASK] * envs)
    agent.cache.keys.normal_()  # type: ignore[union-attr]
    agent.cache.values.normal_()  # type: ignore[union-attr]
    rng = np.random.default_rng(0)
    obs = [rng.normal(size=GROUP.obs_dim).astype(np.float32) for _ in range(envs)]
    rewards, starts = np.ones(envs), np.zeros(envs, dtype=bool)
    agent.act(obs, rewards, ~starts)  # a context begins with an episode start; the timed steps go on from it
    return agent, lambda: agent.act(obs, rewards, starts)


@torch.inference_mode()
def recompute_step_ms(model: Vintix, envs: int, repeats: int) -> float:
    """One step without a cache: embed, backbone and head over the whole window for the last action."""
    window = model.config.context_len
    g = torch.Generator().manual_seed(0)
    obs = torch.randn(envs, window, GROUP.obs_dim, generator=g)
    actions = torch.rand(envs, window, GROUP.act_dim, generator=g)
    rewards = torch.rand(envs, window, generator=g)
    step_num = torch.arange(window).remainder(100).expand(envs, -1)
    task_idx = torch.zeros(envs, dtype=torch.long)

    def step() -> torch.Tensor:
        tokens = model.embed(GROUP.name, task_idx, obs, actions, rewards, step_num)
        return model.head(GROUP.name, model.backbone(tokens)[:, -1])

    return _median_ms(step, repeats)


def time_inference(preset_name: str, envs: int, repeats: int, recompute_repeats: int,
                   window: int | None = None) -> InferenceTiming:
    """Cached first-full and steady-state step latency (and recompute, if `recompute_repeats`)."""
    model = bench_model(preset_name, window)
    window = model.config.context_len
    agent, step = _agent(model, envs)
    cache = agent.cache
    assert cache is not None
    step()  # warm-up: first-call allocations
    # Interleaved, so that load from other jobs on the machine hits both alike.
    first_full, steady = [], []
    for i in range(repeats):
        first_full.append(_median_ms(step, 1, partial(set_cache_state, cache, window - 1)))
        steady.append(_median_ms(step, 1, partial(set_cache_state, cache, 4 * window - 1 + i)))
    recompute = recompute_step_ms(model, envs, recompute_repeats) if recompute_repeats else None
    return InferenceTiming(preset_name, count_parameters(model), window, envs, statistics.median(first_full),
                           statistics.median(steady), recompute)


def literal_steady_state(preset_name: str, envs: int = 1, window_multiple: int = 4) -> tuple[float, float]:
    """Median step latency (ms) of a real run over the window's filling steps vs its last `window`
    steps, after `window_multiple` windows of steps: the cost must not grow with run length."""
    model = bench_model(preset_name)
    window = model.config.context_len
    _, step = _agent(model, envs)
    times = []
    for _ in range(window_multiple * window):
        start = time.perf_counter()
        step()
        times.append((time.perf_counter() - start) * 1000.0)
    return statistics.median(times[window - 16 : window + 16]), statistics.median(times[-window:])
