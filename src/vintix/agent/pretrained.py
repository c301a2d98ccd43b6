"""Models shipped inside the package, loadable by name: ``Agent.from_pretrained("cpu-suite")`` or
``vintix eval --checkpoint cpu-suite``. Each lives in ``agent/pretrained/<name>/`` beside a
``TRAINING.md`` that gives the commands that made it and what they measured."""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

from vintix.model.checkpoint import CONFIG_FILE, CheckpointError
from vintix.train.checkpoint import model_directory


def _shipped_root() -> Path:
    return Path(str(resources.files("vintix.agent").joinpath("pretrained")))


def shipped_models() -> list[str]:
    """Names of the models the package ships."""
    root = _shipped_root()
    return sorted(p.name for p in root.iterdir() if (p / CONFIG_FILE).is_file()) if root.is_dir() else []


def resolve_checkpoint(name_or_path: str | os.PathLike[str]) -> Path:
    """The model folder meant by a path (a checkpoint, or a training run: `model_directory`) or by the
    name of a shipped model; a path that exists always wins over a shipped name."""
    path = Path(name_or_path)
    if path.exists():
        return model_directory(path)
    shipped = _shipped_root() / str(name_or_path)
    if (shipped / CONFIG_FILE).is_file():
        return shipped
    raise CheckpointError(f"{name_or_path}: no such checkpoint or run folder, and no shipped model of that name "
                          f"(shipped: {', '.join(shipped_models()) or 'none'})")
