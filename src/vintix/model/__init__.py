"""Grouped encoders -> causal ALiBi transformer -> grouped action heads (see `model.py`)."""

from vintix.model.checkpoint import CheckpointError, load_pretrained, read_metadata, save_pretrained
from vintix.model.model import (
    PRESETS,
    ActionHead,
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
    "CheckpointError",
    "load_pretrained",
    "read_metadata",
    "save_pretrained",
    "PRESETS",
    "ActionHead",
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
