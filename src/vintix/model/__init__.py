"""Grouped encoders -> causal ALiBi transformer -> grouped action heads (see `model.py`)."""

from vintix.model.model import (
    PRESETS,
    GroupSpec,
    ModelConfig,
    TaskNorm,
    Vintix,
    alibi_bias,
    alibi_slopes,
    attention,
    count_parameters,
    preset,
)

__all__ = [
    "PRESETS",
    "GroupSpec",
    "ModelConfig",
    "TaskNorm",
    "Vintix",
    "alibi_bias",
    "alibi_slopes",
    "attention",
    "count_parameters",
    "preset",
]
