"""Stage: many-shot in-context evaluation, normalized scores against the paper's or our references."""

from vintix.evaluate.run import (
    REWARD_INPUTS,
    EvalConfig,
    EvalConfigError,
    evaluate,
    in_context_score,
    in_context_scorer,
    parse_variation,
    select_tasks,
    shot_curves,
    shots_to_show,
    summarize,
)
from vintix.evaluate.summary import best_k_plateau, converged_gap_with_ci, iqm, iqm_with_ci
from vintix.tasks.scores import REFERENCE_TABLES, Reference, ReferenceScoreError, reference

__all__ = [
    "REFERENCE_TABLES",
    "REWARD_INPUTS",
    "EvalConfig",
    "EvalConfigError",
    "Reference",
    "ReferenceScoreError",
    "best_k_plateau",
    "converged_gap_with_ci",
    "evaluate",
    "in_context_score",
    "in_context_scorer",
    "iqm",
    "iqm_with_ci",
    "parse_variation",
    "reference",
    "select_tasks",
    "shot_curves",
    "shots_to_show",
    "summarize",
]
