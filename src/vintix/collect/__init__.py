"""Stage 3: continuous noise distillation, collecting learning histories (paper Algorithm 1)."""

from vintix.collect.collector import (
    CollectionError,
    CollectionPlan,
    CollectionSettingsError,
    HistorySummary,
    check_demonstrators,
    collect,
    history_seeds,
)
from vintix.collect.noise import NoiseSchedule, mix_action
from vintix.collect.recipe import load_recipe

__all__ = ["CollectionError", "CollectionPlan", "CollectionSettingsError", "HistorySummary", "NoiseSchedule",
           "check_demonstrators", "collect", "history_seeds", "load_recipe", "mix_action"]
