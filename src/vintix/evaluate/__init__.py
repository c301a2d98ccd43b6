"""Stage: many-shot in-context evaluation, normalized scores against the paper's or our references."""

from vintix.evaluate.run import (
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
from vintix.evaluate.scores import REFERENCE_TABLES, Reference, ReferenceScoreError, reference
from vintix.evaluate.summary import best_k_plateau, iqm, iqm_with_ci

__all__ = [
    "REFERENCE_TABLES",
    "EvalConfig",
    "EvalConfigError",
    "Reference",
    "ReferenceScoreError",
    "best_k_plateau",
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
