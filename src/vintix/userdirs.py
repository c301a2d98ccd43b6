"""Where vintix keeps per-user state that is not a result: caches and unfinished runs."""

from __future__ import annotations

import os
from pathlib import Path


def user_cache_dir(name: str) -> Path:
    """``$XDG_CACHE_HOME/vintix/<name>`` (``~/.cache/vintix/<name>``): outside datasets and the package,
    which may be read-only."""
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "vintix" / name
