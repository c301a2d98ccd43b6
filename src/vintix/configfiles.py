"""YAML settings files that build on another (recipes, training configs): a file may name a ``base:`` and give only
what differs from it, as nanoGPT's fine-tuning config does.

    base: darkroom              # a shipped file's name, or a path relative to this file ("../mine.yaml")
    expert_distillation: true   # everything else is the base's

The base is read first (it may have a base of its own), then this file's settings on top of it: mappings merge key
by key (a recipe's ``defaults:`` and ``tasks:``, a config's ``model_overrides:``), any other value replaces the
base's. ``vintix collect|train --print-config`` shows the whole that results.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml

from vintix.atomic import read_regular_text

BASE_KEY = "base"


def merged(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """`over` on top of `base`: mappings merge key by key, any other value replaces the base's."""
    result = dict(base)
    for key, value in over.items():
        result[key] = merged(result[key], value) if isinstance(value, dict) and isinstance(result.get(key), dict) \
            else value
    return result


def read_mapping(path: Path, error: type[Exception], what: str) -> dict[str, Any]:
    """The mapping a YAML file holds (empty for an empty file), or `error` naming the file."""
    try:
        fields = yaml.safe_load(read_regular_text(path)) or {}
    except (yaml.YAMLError, UnicodeDecodeError) as problem:
        raise error(f"{path}: not valid YAML ({' '.join(str(problem).split())})") from None
    if not isinstance(fields, dict):
        raise error(f"{path}: expected a mapping of {what} settings, got {type(fields).__name__}")
    return fields


def read_layered(path: Path, shipped: Callable[[str], Path | None], error: type[Exception], what: str,
                 _chain: tuple[Path, ...] = ()) -> dict[str, Any]:
    """The settings of the YAML file at `path` on top of its ``base:``'s, recursively (module docstring).
    `shipped` finds a shipped file by name (None if there is none); `what` names the kind of file in errors."""
    fields = read_mapping(path, error, what)
    base = fields.pop(BASE_KEY, None)
    if base is None:
        return fields
    if not isinstance(base, str) or not base.strip():
        raise error(f"{path}: {BASE_KEY}: names the {what} this one builds on (a shipped {what}'s name or a file "
                    f"relative to this one), got {base!r}")
    chain = (*_chain, path.resolve())
    base_path = _base_path(base, path, shipped, error, what)
    if base_path.resolve() in chain:
        loop = " -> ".join(str(p) for p in (*chain, base_path.resolve()))
        raise error(f"{path}: {BASE_KEY}: {base} comes back to a file already read ({loop}); a {what} cannot build "
                    "on itself")
    return merged(read_layered(base_path, shipped, error, what, chain), fields)


def _base_path(base: str, including: Path, shipped: Callable[[str], Path | None], error: type[Exception],
               what: str) -> Path:
    """A base named as a file (a path, or a name ending .yaml) is relative to the file naming it; a bare name is a
    shipped file's, so that a base means the same from wherever the command runs."""
    if "/" in base or base.endswith((".yaml", ".yml")):
        path = including.parent / base
        if not path.is_file():
            raise error(f"{including}: {BASE_KEY}: {base}: no such file ({path})")
        return path
    found = shipped(base)
    if found is None:
        raise error(f"{including}: {BASE_KEY}: {base} is no shipped {what}; name a file of your own as a path "
                    f"relative to this one (./{base}.yaml)")
    return found
