"""Stage 2: demonstrators, the experts whose noised actions make learning histories."""

from vintix.demonstrators.base import Demonstrator, load_demonstrator
from vintix.demonstrators.scores import MeasuredScore, our_reference_scores, read_scores
from vintix.demonstrators.scripted import ScriptedMetaWorldDemonstrator
from vintix.demonstrators.trained import TrainedDemonstrator

__all__ = [
    "Demonstrator",
    "MeasuredScore",
    "ScriptedMetaWorldDemonstrator",
    "TrainedDemonstrator",
    "load_demonstrator",
    "our_reference_scores",
    "read_scores",
]
