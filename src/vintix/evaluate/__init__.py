"""Stage: many-shot in-context evaluation, normalized scores against the paper's or our references.

The settings (`EvalConfig` and its defaults) load at once; everything else loads on first use
(PEP 562), because the CLI reads the defaults when it starts and `run` imports torch and the agent.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from vintix.evaluate.config import PLATEAU_SHOTS, REWARD_INPUTS, EvalConfig, EvalConfigError
from vintix.tasks.scores import REFERENCE_TABLES, Reference, ReferenceScoreError, reference

if TYPE_CHECKING:
    from vintix.evaluate.run import (
        ShotResults,
        evaluate,
        evaluate_shots,
        in_context_score,
        in_context_scorer,
        ml1_success,
        parse_variation,
        select_tasks,
        shot_curves,
        shots_to_show,
        summarize,
    )
    from vintix.evaluate.summary import best_k_plateau, converged_gap_with_ci, iqm, iqm_with_ci

_LAZY = {
    "vintix.evaluate.run": ("ShotResults", "evaluate", "evaluate_shots", "in_context_score", "in_context_scorer",
                            "ml1_success", "parse_variation", "select_tasks", "shot_curves", "shots_to_show",
                            "summarize"),
    "vintix.evaluate.summary": ("best_k_plateau", "converged_gap_with_ci", "iqm", "iqm_with_ci"),
}


def __getattr__(name: str) -> Any:
    module = next((module for module, names in _LAZY.items() if name in names), None)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


__all__ = [
    "PLATEAU_SHOTS",
    "REFERENCE_TABLES",
    "REWARD_INPUTS",
    "EvalConfig",
    "EvalConfigError",
    "Reference",
    "ReferenceScoreError",
    "ShotResults",
    "best_k_plateau",
    "converged_gap_with_ci",
    "evaluate",
    "evaluate_shots",
    "in_context_score",
    "in_context_scorer",
    "iqm",
    "iqm_with_ci",
    "ml1_success",
    "parse_variation",
    "reference",
    "select_tasks",
    "shot_curves",
    "shots_to_show",
    "summarize",
]
