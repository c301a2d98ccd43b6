"""A real tiny Vintix for the inference tests: groups and normalization of real tasks, statistics
from short uniform-random rollouts of the real envs (what a trainer computes from its dataset)."""

from __future__ import annotations

from contextlib import contextmanager
from functools import cache

import numpy as np
import pytest
import torch

from conftest import rollout
from vintix.model import GroupSpec, ModelConfig, TaskNorm, Vintix
from vintix.tasks import get_task, make_env

TASKS = ("reach-v3", "push-v3", "InvertedPendulum-v5")


@cache
def real_norm(task: str, steps: int = 150) -> TaskNorm:
    spec = get_task(task)
    env = make_env(task, seed=0)
    observations, _ = rollout(env, steps, reset_seed=0)
    env.close()
    return TaskNorm(task, spec.group, observations.mean(0).tolist(), observations.std(0).tolist(), spec.reward_scale)


def tiny_config(**overrides: object) -> ModelConfig:
    fields = dict(n_layers=2, n_heads=2, obs_emb_dim=15, act_emb_dim=15, rew_emb_dim=2, mlp_dim=64,
                  head_layers=1, context_len=32)
    return ModelConfig(**{**fields, **overrides})


def tiny_model(tasks: tuple[str, ...] = TASKS, seed: int = 0, **overrides: object) -> Vintix:
    """An untrained but real model over `tasks`, in eval mode, fp32."""
    specs = [get_task(t) for t in tasks]
    groups = {s.group: GroupSpec(s.group, s.obs_dim, s.act_dim) for s in specs}
    torch.manual_seed(seed)
    return Vintix(tiny_config(**overrides), list(groups.values()), [real_norm(t) for t in tasks]).eval()


def random_inputs(model: Vintix, group: str, batch: int, steps: int, episode: int = 7, seed: int = 0) -> dict:
    """A model batch of plausible raw inputs: episodes of `episode` steps."""
    g = np.random.default_rng(seed)
    spec = model.groups[group]
    return dict(
        obs=g.normal(size=(batch, steps, spec.obs_dim)).astype(np.float32),
        prev_action=g.uniform(-1, 1, size=(batch, steps, spec.act_dim)).astype(np.float32),
        prev_reward=g.uniform(0, 2, size=(batch, steps)).astype(np.float32),
        step_num=np.broadcast_to(np.arange(steps) % episode, (batch, steps)).copy(),
    )


@contextmanager
def one_thread():
    """Tiny models cost per-op overhead, not FLOPs; with the 2 cores shared by other jobs a second
    intra-op thread only spins (measured: a 300-step eval took 11.4 s on 2 threads, 1.4 s on 1)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


@pytest.fixture(autouse=True)
def one_torch_thread():
    with one_thread():
        yield
