"""Vintix: a cross-domain action model that learns in context (Algorithm Distillation)."""

from vintix.tasks import get_task, list_tasks, make_env

__version__ = "0.1.0"
__all__ = ["get_task", "list_tasks", "make_env"]
