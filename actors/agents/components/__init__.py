"""Agent components (EmbodiedAgents' components without ROS), each in its own module and
imported on first use so that ``import emos.actors.agents`` stays cheap."""
from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "ModelComponent": ".base", "ModelComponentConfig": ".base",
    "LLM": ".llm", "LLMConfig": ".llm",
    "MLLM": ".mllm", "VLM": ".mllm", "MLLMConfig": ".mllm", "VLMConfig": ".mllm",
    "Vision": ".vision", "VisionConfig": ".vision",
    "SpeechToText": ".speech_to_text", "SpeechToTextConfig": ".speech_to_text",
    "TextToSpeech": ".text_to_speech", "TextToSpeechConfig": ".text_to_speech",
    "SemanticRouter": ".semantic_router", "SemanticRouterConfig": ".semantic_router", "Route": ".semantic_router",
    "MapEncoding": ".map_encoding", "MapConfig": ".map_encoding", "MapLayer": ".map_encoding",
    "VideoMessageMaker": ".video_message_maker", "VideoMessageMakerConfig": ".video_message_maker",
    "VLA": ".vla", "VLAConfig": ".vla",
    "Cortex": ".cortex", "CortexConfig": ".cortex",
    "Memory": ".memory", "MemoryConfig": ".memory",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value
