"""Stage 2: demonstrators, the experts whose noised actions make learning histories."""

from vintix.demonstrators.base import Demonstrator, load_demonstrator
from vintix.demonstrators.scripted import ScriptedMetaWorldDemonstrator

__all__ = ["Demonstrator", "ScriptedMetaWorldDemonstrator", "load_demonstrator"]
