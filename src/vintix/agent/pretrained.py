"""Models shipped inside the package, loadable by name: ``Agent.from_pretrained("cpu-suite")`` or
``vintix eval --checkpoint cpu-suite``. Each lives in ``agent/pretrained/<name>/`` in the Hub's layout
(config.json, model.safetensors, a README.md model card) beside a ``TRAINING.md`` that gives the commands
that made it and what they measured; the card carries it too (``scripts/resave_shipped_models.py``)."""

from __future__ import annotations

import fcntl
import hashlib
import os
from importlib import resources
from pathlib import Path

from vintix.errors import local_or_shipped
from vintix.model.checkpoint import CheckpointError, is_checkpoint
from vintix.model.official import CONFIG, METADATA, WEIGHTS, file_sha256, import_official, is_official_snapshot
from vintix.train.checkpoint import model_directory
from vintix.userdirs import user_cache_dir


def _shipped_root() -> Path:
    return Path(str(resources.files("vintix.agent").joinpath("pretrained")))


def shipped_models() -> list[str]:
    """Names of the models the package ships."""
    root = _shipped_root()
    return sorted(p.name for p in root.iterdir() if is_checkpoint(p)) if root.is_dir() else []


def imported_snapshot(snapshot: Path) -> Path:
    """Our checkpoint of an official release snapshot, imported once into the user cache and reused while
    the snapshot's files are unchanged: the cache is keyed on their contents (sha256), so an edited
    config.json or metadata.json, or other weights, is imported afresh."""
    digest = hashlib.sha256()
    for name in (WEIGHTS, CONFIG, METADATA):
        digest.update(file_sha256(snapshot / name).encode())
    directory = user_cache_dir("official") / digest.hexdigest()[:16]
    if is_checkpoint(directory):
        return directory
    # Two evals of one snapshot at once: the second waits for the first's import and reuses it, where the import's
    # own folder lock would refuse it.
    locks = user_cache_dir("official-imports")  # beside the cache, which holds imports only
    locks.mkdir(parents=True, exist_ok=True)
    with open(locks / f"{directory.name}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not is_checkpoint(directory):
            import_official(snapshot, directory, overwrite=True)  # the cache's own folder: a failed import's leftover
    return directory


def resolve_checkpoint(name_or_path: str | os.PathLike[str]) -> Path:
    """The model folder meant by a path (a checkpoint, a training run: `model_directory`, or an official
    release snapshot: `imported_snapshot`) or by the name of a shipped model; a bare name that is both is refused
    (`vintix.errors.local_or_shipped`: ``./name`` is the path)."""
    path = Path(name_or_path)
    shipped = _shipped_root() / path.name
    if not local_or_shipped(name_or_path, path.name == str(name_or_path) and is_checkpoint(shipped), "model"):
        return shipped
    if is_official_snapshot(path):
        return imported_snapshot(path)
    if path.exists():
        return model_directory(path)
    raise CheckpointError(f"{name_or_path}: no such checkpoint or run folder, and no shipped model of that name "
                          f"(shipped: {', '.join(shipped_models()) or 'none'})")


def shipped_name(resolved: Path) -> str | None:
    """The name of the shipped model whose folder `resolved` (`resolve_checkpoint`'s answer) is, else None."""
    return resolved.name if resolved.parent == _shipped_root() else None


def checkpoint_name(given: str | os.PathLike[str], resolved: Path) -> str:
    """How results name the checkpoint they came from, without this machine's absolute paths where that
    can be helped: a shipped model by its name, an imported release snapshot by the folder given, a
    checkpoint under the working directory relative to it, any other by its path."""
    if (name := shipped_name(resolved)) is not None:
        return name
    if is_official_snapshot(Path(given)):
        return str(given)
    try:
        return str(resolved.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(resolved)
