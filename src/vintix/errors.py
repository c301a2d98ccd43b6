"""Exceptions that carry a message a user can act on: what went wrong, and the fix."""

from __future__ import annotations


class VintixError(Exception):
    """Base class of every error vintix raises on purpose."""


class UnknownTaskError(VintixError, ValueError):
    """A task name that is not in the registry (the message lists close matches)."""


class UnsupportedOptionError(VintixError, ValueError):
    """An environment option (e.g. a physics variation) that the task's domain does not have."""


class MissingDependencyError(VintixError, ImportError):
    """An optional package a domain needs is not installed (the message says what to install)."""
