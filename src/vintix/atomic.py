"""Atomic file writes: a file appears complete under its final name, or not at all."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

PARTIAL_SUFFIX = ".partial"


def partial_path(path: str | os.PathLike[str]) -> Path:
    """The temporary sibling that holds a file until it is complete (same directory, so the final
    rename is atomic on POSIX filesystems)."""
    path = Path(path)
    return path.with_name(path.name + PARTIAL_SUFFIX)


def publish(temporary: Path, final: str | os.PathLike[str]) -> None:
    """Give a finished temporary file its final name."""
    # Without fsync, a crash shortly after the rename can leave the new name pointing at empty blocks.
    fd = os.open(temporary, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(temporary, final)


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside `path`; publish it as `path` when the block succeeds, delete it
    when the block raises."""
    final = Path(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    temporary = partial_path(final)
    try:
        yield temporary
        publish(temporary, final)
    finally:
        temporary.unlink(missing_ok=True)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write `text` to `path` atomically."""
    with atomic_path(path) as temporary:
        temporary.write_text(text)
