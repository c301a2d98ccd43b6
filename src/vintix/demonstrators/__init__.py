"""Stage 2: demonstrators, the experts whose noised actions make learning histories."""

from vintix.demonstrators.base import BEHAVIOURS, Demonstrator, load_demonstrator
from vintix.demonstrators.posterior import GoalInferringDemonstrator, PosteriorSamplingDemonstrator
from vintix.demonstrators.scripted import ScriptedMetaWorldDemonstrator
from vintix.demonstrators.trained import TrainedDemonstrator

__all__ = [
    "BEHAVIOURS",
    "GoalInferringDemonstrator",
    "PosteriorSamplingDemonstrator",
    "Demonstrator",
    "ScriptedMetaWorldDemonstrator",
    "TrainedDemonstrator",
    "load_demonstrator",
]
