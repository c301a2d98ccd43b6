"""Normalized scores, ``(R − random) / (expert − random)``, against either reference table.

Two tables, chosen by name: ``paper`` (the paper's published random/expert returns, in the task
registry; the default, so numbers compare with the paper's) and ``ours`` (the returns of our own
demonstrators and of a uniform-random policy, measured on our env versions by `vintix demonstrator
eval`; see `vintix.demonstrators.scores`). A task the chosen table lacks gets no normalized score and
a message saying so, never a made-up one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vintix.errors import VintixError
from vintix.tasks import get_task

REFERENCE_TABLES = ("paper", "ours")


class ReferenceScoreError(VintixError, ValueError):
    """A reference table that cannot normalize a task (expert not above random)."""


@dataclass(frozen=True)
class Reference:
    """A task's random and expert returns in one table, with where they came from."""

    random: float
    expert: float
    provenance: str

    def __post_init__(self) -> None:
        # expert ≤ random would flip or blow up every score (and expert == random would make every
        # return "expert"), so it is an error, never silently 1.
        if not self.expert > self.random:
            raise ReferenceScoreError(
                f"expert return {self.expert} is not above random return {self.random} ({self.provenance}); "
                "such a reference cannot normalize scores: re-measure the demonstrator or use the other table"
            )

    def normalize(self, returns: float | np.ndarray) -> np.ndarray:
        """Normalized score(s) of episode return(s)."""
        return (np.asarray(returns, dtype=np.float64) - self.random) / (self.expert - self.random)


def check_table(table: str) -> str:
    """`table` if it names a reference table; a ReferenceScoreError listing them otherwise."""
    if table not in REFERENCE_TABLES:
        raise ReferenceScoreError(f"unknown reference table {table!r}; choose one of {', '.join(REFERENCE_TABLES)}")
    return table


def reference(task: str, table: str = "paper") -> Reference | None:
    """`task`'s reference in `table` ('paper' or 'ours'); None when the table has no score for it."""
    check_table(table)
    spec = get_task(task)
    if table == "paper":
        if spec.paper_random is None or spec.paper_expert is None:
            return None  # not a task of the paper
        return Reference(spec.paper_random.mean, spec.paper_expert.mean, spec.paper_expert.provenance)
    if table == "ours":
        from vintix.demonstrators.scores import our_reference_scores

        found = our_reference_scores(spec.name)
        if found is None:
            return None
        random, expert = found
        return Reference(random.mean, expert.mean, expert.provenance)
    raise AssertionError(table)  # check_table admitted a table this function does not know


def missing_reference_note(tasks: list[str], table: str) -> str:
    """What to tell a user whose table lacks `tasks`."""
    return (f"no '{table}' reference score (random and demonstrator returns) for {len(tasks)} task(s): "
            f"{', '.join(tasks)}; their normalized_{table} scores are left empty. Measure them with "
            f"`vintix demonstrator eval --task TASK`.")
