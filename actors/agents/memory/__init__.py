"""Spatio-temporal memory (EmbodiedAgents' eMEM): what the robot saw and did, where and when.

:mod:`.store` is the index (pure: numpy and a vector store handed in), :mod:`.tools` the tool
specs a language model queries it with; the ``Memory`` component wires them to topics.
"""
from .store import MemoryQueryError, MemoryRecord, MemoryStore
from .tools import MEMORY_TOOLS

__all__ = ["MemoryStore", "MemoryRecord", "MemoryQueryError", "MEMORY_TOOLS"]
