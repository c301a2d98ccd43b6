"""MuJoCo tasks through gymnasium, with the paper's parametric variations (§4.3).

Variations are written into the compiled MuJoCo model (`model.opt`), which `reset` never touches, so
they hold for the env's whole life; the agent is never told about them.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym

from vintix.errors import UnsupportedOptionError


def make_mujoco_env(
    env_id: str,
    viscosity: float | None = None,
    gravity_scale: float | None = None,
    render_mode: str | None = None,
    **env_kwargs: Any,
) -> gym.Env:
    """gymnasium's env `env_id` (made with `env_kwargs`), optionally with another viscosity (paper: 0.05,
    0.1) or gravity scaled by `gravity_scale` (paper: 0.9, 1.1)."""
    env = gym.make(env_id, render_mode=render_mode, **env_kwargs)
    try:
        apply_physics_variation(env, viscosity=viscosity, gravity_scale=gravity_scale)
    except BaseException:
        env.close()
        raise
    return env


def apply_physics_variation(env: gym.Env, viscosity: float | None = None, gravity_scale: float | None = None) -> None:
    """Change the medium's viscosity and/or scale gravity of a gymnasium MuJoCo env in place."""
    model = env.unwrapped.model  # type: ignore[attr-defined]
    # MuJoCo takes any double, NaN included, and the episode then silently goes NaN.
    if viscosity is not None and not (math.isfinite(viscosity) and viscosity >= 0):
        raise UnsupportedOptionError(f"viscosity must be >= 0 and finite (paper: 0.05, 0.1), got {viscosity}")
    if gravity_scale is not None and not math.isfinite(gravity_scale):
        raise UnsupportedOptionError(f"gravity_scale must be finite (paper: 0.9, 1.1), got {gravity_scale}")
    if viscosity is not None:
        model.opt.viscosity = viscosity
    if gravity_scale is not None:
        model.opt.gravity[:] = model.opt.gravity * gravity_scale
