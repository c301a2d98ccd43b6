"""Type checks for the config dataclasses, whose values often arrive as YAML or ``--set`` strings.

A dataclass does not check its annotations, so ``max_steps: int`` happily holds ``"abc"`` and fails
later, deep in a comparison. `check_field_types` checks every field against its annotation before
anything runs, and makes the harmless conversions (an int where a float is meant, a Path where a
str is meant).
"""

from __future__ import annotations

import ast
import dataclasses
import functools
import itertools
import json
import math
import os
import types
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from vintix.atomic import read_regular_text
from vintix.errors import json_loads

T = TypeVar("T")

_INVALID = object()


def _coerce(value: Any, hint: Any) -> Any:
    """`value` as the type `hint` names, or `_INVALID`. Generic types it does not know pass unchecked."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        for arg in args:
            result = _coerce(value, arg)
            if result is not _INVALID:
                return result
        return _INVALID
    if hint is Any:
        return value
    if hint is type(None):
        return value if value is None else _INVALID
    if hint is bool:
        return value if isinstance(value, bool) else _INVALID
    if hint is int:
        return value if isinstance(value, int) and not isinstance(value, bool) else _INVALID
    if hint is float:  # NaN or inf is no setting's meaningful value
        if isinstance(value, str):  # YAML 1.1 reads 3e-4 (no dot) as a string; the docs write it so
            value = _number(value)
        number = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        return float(value) if number else _INVALID
    if hint is str:
        return value if isinstance(value, str) else str(value) if isinstance(value, os.PathLike) else _INVALID
    if hint is Path:
        return Path(value) if isinstance(value, (str, os.PathLike)) else _INVALID
    if origin in (list, tuple):  # tuple[X, ...] only: a list of any length, kept as the annotation's type
        if not isinstance(value, (list, tuple)):
            return _INVALID
        items = [_coerce(item, args[0]) for item in value]
        return _INVALID if any(item is _INVALID for item in items) else origin(items)
    if origin is dict:
        if not isinstance(value, dict):
            return _INVALID
        pairs = [(_coerce(k, args[0]), _coerce(v, args[1])) for k, v in value.items()]
        return _INVALID if any(_INVALID in pair for pair in pairs) else dict(pairs)
    if isinstance(hint, type) and origin is None:  # a class of ours, e.g. CollectionPlan.schedule: NoiseSchedule
        return value if isinstance(value, hint) else _INVALID
    return value


def _number(text: str) -> float | str:
    """`text` as the number it spells (``3e-4``), or `text` itself."""
    try:
        return float(text)
    except ValueError:
        return text


def type_name(hint: Any) -> str:
    """``int``, ``float | None``, ``list[str]``: an annotation as a user reads it."""
    if isinstance(hint, type) and not typing.get_args(hint):
        return "None" if hint is type(None) else hint.__name__
    return str(hint).replace("typing.", "").replace("pathlib.", "").replace("NoneType", "None")


def check_field_types(instance: Any, error: type[Exception]) -> None:
    """Check (and convert in place) every field of a dataclass instance against its annotation;
    raise `error` naming the first field that does not fit."""
    hints = typing.get_type_hints(type(instance))
    for field in dataclasses.fields(instance):
        value = getattr(instance, field.name)
        converted = _coerce(value, hints[field.name])
        if converted is _INVALID:
            raise error(f"{type(instance).__name__}.{field.name} must be {type_name(hints[field.name])}, got {value!r}")
        object.__setattr__(instance, field.name, converted)  # works for frozen dataclasses too


MAX_THREADS = 1024
"""The most torch CPU threads vintix sets: more is a typo (torch would try to start them all)."""


def check_threads(threads: object, what: str = "threads") -> int:
    """`threads` as a count of torch CPU threads, 1 to `MAX_THREADS`, or a ValueError naming `what` (a bool, a
    float or a string is not a count, even where Python would take it as one)."""
    if isinstance(threads, bool) or not isinstance(threads, int) or not 1 <= threads <= MAX_THREADS:
        raise ValueError(f"{what} must be a whole number of CPU threads from 1 to {MAX_THREADS}, got {threads!r}")
    return threads


@functools.cache
def field_docs(module: str, cls: str) -> dict[str, str]:
    """The docstring under each field of the dataclass `cls` of `module` (``"vintix.train.config"``), each on one
    line: the one text that documents a setting, in the code and as its command-line option's help. Read from the
    module's source, not by importing it, so that ``vintix --help`` imports none of the stages."""
    path = Path(__file__).parent.joinpath(*module.split(".")[1:]).with_suffix(".py")
    tree = ast.parse(path.read_text(), str(path))
    found = next((node for node in tree.body if isinstance(node, ast.ClassDef) and node.name == cls), None)
    if found is None:
        raise LookupError(f"{path} has no class {cls}")
    docs = {}
    for field, after in itertools.pairwise(found.body):
        if (isinstance(field, ast.AnnAssign) and isinstance(field.target, ast.Name) and isinstance(after, ast.Expr)
                and isinstance(after.value, ast.Constant) and isinstance(after.value.value, str)):
            docs[field.target.id] = " ".join(after.value.value.split())
    return docs


def field_help(module: str, cls: str, field: str) -> str:
    """`field`'s docstring (`field_docs`): a command-line option's help for that field."""
    docs = field_docs(module, cls)
    if field not in docs:
        raise LookupError(f"{module}.{cls}.{field} has no docstring to serve as its option's help")
    return docs[field]


def available_cores() -> int:
    """The CPU cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def capped_threads(requested: int, note: Callable[[str], object]) -> int:
    """`requested` torch threads, or the cores this process may use where it asks for more (with a `note`): threads
    beyond the cores only slow torch down, and each brings its own buffers (1,024 of them ran out of 8 GB)."""
    cores = available_cores()
    if requested <= cores:
        return requested
    note(f"--threads {requested} is more than the {cores} cores this process may use: using {cores}")
    return cores


FileError = Callable[[Path, str], Exception]
"""How a JSON reader raises: given the file and "<problem>; <fix>" (`DatasetError` is one; `errors.at_file` makes
one of an error class that takes a single message)."""


def read_json_object(path: Path, error: FileError, fix: str) -> dict[str, Any]:
    """The JSON object in the file at `path`, or `error` for a file that is not JSON or not an object. Read through
    `read_regular_text`: a FIFO in a file's place is an error, not a hang."""
    try:
        data = json_loads(read_regular_text(path))
    except (json.JSONDecodeError, UnicodeDecodeError) as problem:
        raise error(path, f"not valid JSON ({problem}); {fix}") from None
    if not isinstance(data, dict):
        raise error(path, f"expected a JSON object, got {type(data).__name__}; {fix}")
    return data


def checked_fields(data: dict[str, Any], schema: type[T], path: Path, error: FileError, fix: str,
                   within: str = "") -> T:
    """`data` (a JSON object read from `path`) as the dataclass `schema`: each field present unless it has a default,
    each of its annotated type (`_coerce`), keys the schema does not name ignored (a newer writer's). `error` names
    the file, the field (inside the object `within`, if given) and the type it expected, then `fix`."""
    hints = typing.get_type_hints(schema)
    values = {}
    for field in dataclasses.fields(schema):  # type: ignore[arg-type]
        name = f"{within}.{field.name}" if within else field.name
        if field.name not in data:
            if field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING:
                raise error(path, f"no field {name!r} ({type_name(hints[field.name])}); {fix}")
            continue
        converted = _coerce(data[field.name], hints[field.name])
        if converted is _INVALID:
            shown = json.dumps(data[field.name], default=str)
            raise error(path, f"field {name!r} must be {type_name(hints[field.name])}, got "
                              f"{shown if len(shown) <= 60 else shown[:59] + '…'}; {fix}")
        values[field.name] = converted
    return schema(**values)


def read_json_file(path: Path, schema: type[T], error: FileError, fix: str) -> T:
    """The JSON object in the file at `path` as the dataclass `schema`, the one way every JSON file vintix reads is
    checked (`read_json_object`, then `checked_fields`)."""
    return checked_fields(read_json_object(path, error, fix), schema, path, error, fix)
