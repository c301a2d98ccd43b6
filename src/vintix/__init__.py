"""Vintix: a cross-domain action model that learns in context (Algorithm Distillation)."""

from vintix.tasks import get_task, list_tasks, make_env
from vintix.tasks.custom import register_task

__version__ = "0.1.0"
__all__ = ["Agent", "get_task", "list_tasks", "make_env", "register_task"]


def __getattr__(name: str) -> object:
    # `vintix.Agent` on first use: importing the package (every CLI command does) stays free of torch.
    if name == "Agent":
        from vintix.agent import Agent

        return Agent
    raise AttributeError(f"module 'vintix' has no attribute {name!r}")
