"""Stage 1 of the pipeline: the task registry and the environment factory."""

from vintix.tasks.make import (
    ActionSpaceError,
    action_box,
    action_space_of,
    gymnasium_id,
    make_env,
    register_gymnasium_envs,
    task_action_space,
)
from vintix.tasks.registry import (
    DOMAINS,
    ReferenceScore,
    TaskSpec,
    find_task,
    get_task,
    list_tasks,
    resolve_tasks,
    select_tasks,
)

register_gymnasium_envs()

__all__ = [
    "ActionSpaceError",
    "DOMAINS",
    "ReferenceScore",
    "TaskSpec",
    "action_box",
    "action_space_of",
    "find_task",
    "get_task",
    "gymnasium_id",
    "list_tasks",
    "make_env",
    "resolve_tasks",
    "select_tasks",
    "task_action_space",
]
