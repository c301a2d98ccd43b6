"""Learning-history datasets in the official Vintix format: writer, lazy reader, discovery, validation."""

from vintix.data.discovery import (
    TaskData,
    find_tasks,
    history_paths,
    metadata_dims,
    read_task_metadata,
    register_dataset_task,
    task_directory,
    task_dirs,
    write_task_metadata,
)
from vintix.data.layout import DTYPES, MAX_GROUP_ROWS
from vintix.data.reader import LearningHistory
from vintix.data.validate import Problem, TaskSummary, summarize_dataset, validate_dataset, validate_task
from vintix.data.writer import LearningHistoryWriter
from vintix.errors import DatasetError

__all__ = [
    "DTYPES",
    "MAX_GROUP_ROWS",
    "DatasetError",
    "LearningHistory",
    "LearningHistoryWriter",
    "Problem",
    "TaskData",
    "TaskSummary",
    "find_tasks",
    "history_paths",
    "metadata_dims",
    "read_task_metadata",
    "register_dataset_task",
    "summarize_dataset",
    "task_directory",
    "task_dirs",
    "validate_dataset",
    "validate_task",
    "write_task_metadata",
]
