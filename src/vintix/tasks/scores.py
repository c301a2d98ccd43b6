"""Reference scores, facts about tasks: normalized scores ``(R − random) / (expert − random)`` against
either reference table, and the table of our own measured scores.

Two tables, chosen by name: ``paper`` (the paper's published random/expert returns, in the task
registry; the default, so numbers compare with the paper's) and ``ours`` (the returns of our own
demonstrators and of a uniform-random policy, measured on our env versions by `vintix demonstrator
eval`, which `vintix.demonstrators.scores` runs). A task the chosen table lacks gets no normalized
score and a message saying so, never a made-up one.

The paper's published scores come from other env versions (MuJoCo v4, Meta-World v2) and other
demonstrators, so normalizing by our demonstrators' measured scores is the fair yardstick for data
we collect; the package's ``demonstrators/scores.csv`` keeps them, one row per (task, policy), each
with how it was measured (episodes, seed, env and package versions, date, command). That table
normalizes every result, so it is reference data, read-only at run time: `vintix demonstrator eval`
writes what it measures to a table in the user's folder, and rewrites the package's only when asked
to (``--update-package-table``).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields
from functools import cache
from importlib import resources
from pathlib import Path

import numpy as np

from vintix.atomic import atomic_write_text
from vintix.errors import VintixError
from vintix.tasks.registry import ReferenceScore, get_task

REFERENCE_TABLES = ("paper", "ours")
POLICIES = ("demonstrator", "random")
"""The policies of a row of our score table."""


class ReferenceScoreError(VintixError, ValueError):
    """A reference table that cannot normalize a task (expert not above random)."""


@dataclass(frozen=True)
class Reference:
    """A task's random and expert returns in one table, with where they came from."""

    random: float
    expert: float
    provenance: str
    per_goal: bool = False
    """whether a return is first divided by its run's own optimal return (the discrete benchmarks, whose best
    return depends on where the hidden goal is): the score is then the fraction of the optimal"""

    def __post_init__(self) -> None:
        # expert ≤ random would flip or blow up every score (and expert == random would make every
        # return "expert"), so it is an error, never silently 1.
        if not self.expert > self.random:
            raise ReferenceScoreError(
                f"expert return {self.expert} is not above random return {self.random} ({self.provenance}); "
                "such a reference cannot normalize scores: re-measure the demonstrator or use the other table"
            )

    def normalize(self, returns: float | np.ndarray, optimal: float | np.ndarray | None = None) -> np.ndarray:
        """Normalized score(s) of episode return(s); a `per_goal` reference needs each run's `optimal` return."""
        returns = np.asarray(returns, dtype=np.float64)
        if self.per_goal:
            if optimal is None:
                raise ReferenceScoreError(f"{self.provenance}: a score needs the run's optimal return, which this "
                                          "result table lacks (its 'optimal' column); re-run `vintix eval`")
            returns = returns / np.asarray(optimal, dtype=np.float64)
        return (returns - self.random) / (self.expert - self.random)


OPTIMAL_PROVENANCE = "the optimal return of the run's own hidden goal (vintix.tasks.discrete_benchmarks)"
ENV_OPTIMUM_REFERENCE = Reference(0.0, 1.0, "the optimal return the env gives for each run's own goal (its "
                                  "optimal_return())", per_goal=True)
"""The 'ours' reference of a task of your own with no reference scores whose env offers `optimal_return`."""


def check_table(table: str) -> str:
    """`table` if it names a reference table; a ReferenceScoreError listing them otherwise."""
    if table not in REFERENCE_TABLES:
        raise ReferenceScoreError(f"unknown reference table {table!r}; choose one of {', '.join(REFERENCE_TABLES)}")
    return table


def reference(task: str, table: str = "paper", env_optimum: bool = False) -> Reference | None:
    """`task`'s reference in `table` ('paper' or 'ours'); None when the table has no score for it. `env_optimum`: the
    runs' env gave each goal's optimal return (`optimal_return()`), which scores a task of your own that registered
    no reference scores in 'ours', as on the discrete benchmarks."""
    check_table(table)
    spec = get_task(task)
    if spec.domain == "custom":  # its own references, whichever table: no table knows it
        if spec.reference_random is None or spec.reference_expert is None:
            return ENV_OPTIMUM_REFERENCE if env_optimum and table == "ours" else None
        return Reference(spec.reference_random, spec.reference_expert, "registered with the task")
    if spec.domain == "icrl":  # no published table: the optimal return of each run's own hidden goal
        return None if table == "paper" else Reference(0.0, 1.0, OPTIMAL_PROVENANCE, per_goal=True)
    if table == "paper":
        if spec.paper_random is None or spec.paper_expert is None:
            return None  # not a task of the paper
        return Reference(spec.paper_random.mean, spec.paper_expert.mean, spec.paper_expert.provenance)
    if table == "ours":
        found = our_reference_scores(spec.name)
        if found is None:
            return None
        random, expert = found
        return Reference(random.mean, expert.mean, expert.provenance)
    raise AssertionError(table)  # check_table admitted a table this function does not know


def missing_reference_note(tasks: list[str], table: str) -> str:
    """What to tell a user whose table lacks `tasks`: the paper's lacks the tasks it never ran (nothing to
    measure), ours those whose demonstrator and random policy were not measured yet."""
    if table == "paper":
        return (f"no 'paper' reference score (random and demonstrator returns) for {len(tasks)} task(s) the paper "
                f"never ran: {', '.join(tasks)}; their normalized_paper scores are left empty (--reference ours "
                "scores them)")
    return (f"no '{table}' reference score (random and demonstrator returns) for {len(tasks)} task(s): "
            f"{', '.join(tasks)}; their normalized_{table} scores are left empty. Measure them with "
            f"`vintix demonstrator eval --task TASK`.")


def scores_path() -> Path:
    """The package's score table (``demonstrators/scores.csv``, beside the demonstrators it measures)."""
    return Path(str(resources.files("vintix").joinpath("demonstrators").joinpath("scores.csv")))


@dataclass(frozen=True)
class MeasuredScore:
    """One row of the score table: a policy's episode returns on one task, and how they were measured."""

    task: str
    policy: str
    """'demonstrator' or 'random'."""
    mean: float
    std: float
    episodes: int
    seed: int
    env_version: str
    """gymnasium id and the simulator package's version: returns drift across versions."""
    measured_on: str
    command: str

    def reference(self) -> ReferenceScore:
        return ReferenceScore(self.mean, self.std, f"ours: {self.policy}, {self.episodes} episodes, seed "
                              f"{self.seed}, {self.env_version}, {self.measured_on}")


def read_scores(path: Path | None = None) -> list[MeasuredScore]:
    """Every row of the score table (none if it does not exist yet)."""
    path = path or scores_path()
    if not path.is_file():
        return []
    rows = csv.DictReader(path.read_text().splitlines())
    columns = [f.name for f in fields(MeasuredScore)]
    if rows.fieldnames is None or not set(columns) <= set(rows.fieldnames):
        raise VintixError(f"{path}: not a score table (its columns are {', '.join(columns)}); write the scores to "
                          "another file, or remove it")
    try:
        return [MeasuredScore(task=row["task"], policy=row["policy"], mean=float(row["mean"]), std=float(row["std"]),
                              episodes=int(row["episodes"]), seed=int(row["seed"]), env_version=row["env_version"],
                              measured_on=row["measured_on"], command=row["command"]) for row in rows]
    except (TypeError, ValueError) as error:  # a short row gives None, a mangled number a ValueError
        raise VintixError(f"{path}, line {rows.line_num}: not a row of a score table ({error}); fix or remove "
                          "it") from None


def record_scores(new: Sequence[MeasuredScore], path: Path) -> Path:
    """Add rows to the score table at `path`, replacing any earlier row of the same (task, policy).

    `path` has no default: rewriting the package's reference table (`scores_path()`) has to be asked for.
    """
    replaced = {(s.task, s.policy) for s in new}
    rows = [s for s in read_scores(path) if (s.task, s.policy) not in replaced] + list(new)
    rows.sort(key=lambda s: (s.task, POLICIES.index(s.policy)))
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=[f.name for f in fields(MeasuredScore)], lineterminator="\n")
    writer.writeheader()
    writer.writerows(asdict(s) for s in rows)
    atomic_write_text(path, buffer.getvalue())
    return path


def our_reference_scores(task: str, path: Path | None = None) -> tuple[ReferenceScore, ReferenceScore] | None:
    """(random, expert) as measured here for `task`, or None if either was never measured."""
    name = get_task(task).name
    found = {s.policy: s.reference() for s in read_scores(path) if s.task == name}
    if not set(POLICIES) <= set(found):
        return None
    return found["random"], found["demonstrator"]


MODEL_CARD_DOMAIN_IQM = {"mujoco": 0.99, "metaworld": 0.99, "bidexhands": 0.92, "industrial_benchmark": 0.99}
"""The released model's per-domain IQM of normalized score, from its model card"""


@cache
def model_card_scores() -> dict[str, float]:
    """The released model's per-task normalized scores from its model card (``dunnolab/Vintix`` README), by
    our task name (``model_card_scores.csv`` keeps the card's names). The card normalizes with its own
    references (Hopper: an expert of 3,246, not the paper table's 2,350): compare, do not subtract."""
    text = resources.files("vintix.tasks").joinpath("model_card_scores.csv").read_text()
    return {row["task"]: float(row["normalized_score"]) for row in csv.DictReader(io.StringIO(text))}
