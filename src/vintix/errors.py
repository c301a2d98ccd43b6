"""Exceptions that carry a message a user can act on: what went wrong, and the fix."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")


class VintixError(Exception):
    """Base class of every error vintix raises on purpose."""


class UnknownTaskError(VintixError, ValueError):
    """A task name that is not in the registry (the message lists close matches)."""


class UnsupportedOptionError(VintixError, ValueError):
    """An environment option (e.g. a physics variation) that the task's domain does not have."""


class MissingDependencyError(VintixError, ImportError):
    """An optional package a domain needs is not installed (the message says what to install)."""


class DatasetError(VintixError, ValueError):
    """A dataset file or folder that breaks the format; ``str()`` reads "<path>: <problem and fix>"."""

    def __init__(self, path: str | os.PathLike[str], problem: str) -> None:
        # Both parts are kept in args so the error survives pickling (DataLoader workers re-raise it).
        super().__init__(Path(path), problem)
        self.path = Path(path)
        self.problem = problem

    def __str__(self) -> str:
        return f"{self.path}: {self.problem}"


class OutputPathError(VintixError, OSError):
    """An output path that cannot be written because a file sits where a folder has to be."""


class DiskSpaceError(VintixError, OSError):
    """Less free space than a command's output needs, found before it writes (`vintix.atomic.check_free_space`); its
    message names the folder, both sizes and the fix."""

    def __str__(self) -> str:
        return str(self.strerror)


class DeviceError(VintixError, ValueError):
    """A torch device name that is unknown, or that this machine does not have (CUDA without a GPU)."""


class PluginError(VintixError, RuntimeError):
    """Code vintix was told to call (a task's env factory, a demonstrator, a model file's library) raised."""


def call_plugin(what: str, fix: str, function: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """``function(*args, **kwargs)``, where `function` is code of the user's (or a library's) that vintix calls:
    an exception it raises becomes one PluginError line that names `what` raised what, and `fix`, instead of a
    traceback from deep inside the pipeline. vintix's own errors pass through."""
    try:
        return function(*args, **kwargs)
    except VintixError:
        raise
    # SystemExit too: a plug-in that calls sys.exit() would otherwise end the command with its code, often 0,
    # having done nothing.
    except (Exception, SystemExit) as error:  # noqa: BLE001 - any exception of foreign code is named, not swallowed
        raise PluginError(f"{what} raised {type(error).__name__}: {error}. {fix}") from error


class ShadowedNameError(VintixError, ValueError):
    """A bare name that means both something the package ships and a file or folder here."""


def local_or_shipped(given: str | os.PathLike[str], shipped: bool, what: str, a_file: bool = False) -> bool:
    """Whether `given` means the local path (True) or the package's shipped `what` of that name (False), one way
    only: a bare name (no folder part) that is both is a ShadowedNameError, never silently the local one (which
    runs would then record as the shipped one). ``./name`` means the local path, always. `a_file`: `what` is a file
    (a recipe, a config), so a folder of that name (a run, a model called the same) is not one and shadows nothing."""
    text = os.fspath(given)
    exists = os.path.lexists(text) and not (a_file and os.path.isdir(text))
    if exists and shipped and os.sep not in text and "/" not in text:
        raise ShadowedNameError(f"{text!r} is both the shipped {what} of that name and {os.path.join('.', text)} here; "
                                f"write ./{text} for yours, or rename or move it to use the shipped one")
    return exists or not shipped


def at_file(error: type[Exception]) -> Callable[[Path, str], Exception]:
    """An error class that takes one message, as a JSON reader's error (`vintix.fields.FileError`): given a file and
    its problem, the message "<file>: <problem>"."""
    return lambda path, problem: error(f"{path}: {problem}")


def json_loads(text: str) -> Any:
    """`json.loads`, where a file nested too deeply for Python's parser (a RecursionError, from a hostile file of
    a few hundred kilobytes) is a `json.JSONDecodeError` like any other malformed JSON, for its reader to name."""
    try:
        return json.loads(text)
    except RecursionError:
        raise json.JSONDecodeError("nested too deeply to read", text[:100], 0) from None


def printable(text: str, breaks: bool = True) -> str:
    """`text` with every control character but line breaks and tabs written as an escape (``\\x1b``): what a file
    supplied (a task name, a label, a lock's note) is printed as it is, and never moves a terminal's cursor or
    colours it. `breaks` False: line breaks and tabs escaped too, for a name, which must not start a line of its
    own in a message or a figure."""
    kept = "\n\t" if breaks else ""
    return "".join(c if c.isprintable() or c in kept else ascii(c)[1:-1] for c in text)
