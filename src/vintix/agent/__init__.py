"""Stage: the in-context agent, a batched stateful policy with a sliding-window KV cache."""

from vintix.agent.agent import Agent, AgentInputError, AgentOutputError, AgentStateError, AgentTask, resolve_task
from vintix.agent.cache import KVCache, banded_forward, cached_backbone
from vintix.agent.pretrained import resolve_checkpoint, shipped_models

__all__ = ["Agent", "AgentInputError", "AgentOutputError", "AgentStateError", "AgentTask", "KVCache", "banded_forward",
           "cached_backbone", "resolve_checkpoint", "resolve_task", "shipped_models"]
