"""EMOS intelligence core (EmbodiedAgents without ROS): model specs, clients and their types.

Submodules are imported lazily so ``import emos.actors.agents`` stays cheap: heavy parts
(sentence-transformers, chromadb, torch) load only when something asks for them.
"""
from __future__ import annotations

import importlib
from typing import Any

from .errors import (
    MalformedResponseError,
    ModelClientError,
    ModelConnectionError,
    ModelNotFoundError,
    ModelServerError,
    ModelTimeoutError,
)
from .types import (
    ActionChunk,
    ChatChunk,
    ChatMessage,
    ChatRequest,
    ChatResponse,
    Detection2D,
    DetectionRequest,
    DetectionResponse,
    EmbeddingRequest,
    EmbeddingResponse,
    ImageData,
    PolicyObservation,
    SpeechRequest,
    SpeechResponse,
    ToolCall,
    ToolSpec,
    TranscriptionRequest,
    TranscriptionResponse,
)

# public name -> submodule that defines it; resolved on first attribute access (PEP 562).
_MODELS = ("GenericLLM", "GenericMLLM", "GenericTTS", "GenericSTT", "OllamaModel", "TransformersLLM",
           "TransformersMLLM", "LeRobotPolicy", "RoboBrain2", "Whisper", "SpeechT5", "Bark", "MeloTTS",
           "VisionModel", "model_from_dict")
_CLIENTS = ("ModelClient", "GenericHTTPClient", "OllamaClient", "RoboMLHTTPClient", "RoboMLWSClient",
            "RoboMLRESPClient", "LeRobotClient", "client_from_serialized")
_LAZY: dict[str, str] = {
    **{name: ".models" for name in _MODELS},
    **{name: ".clients" for name in _CLIENTS},
    "ChromaDB": ".db",
    "ChromaClient": ".db",
    # components and their configs (recipes: ``from emos.actors.agents import LLM, LLMConfig``)
    **{name: ".components" for name in (
        "LLM", "LLMConfig", "MLLM", "VLM", "MLLMConfig", "VLMConfig", "Vision", "VisionConfig",
        "SpeechToText", "SpeechToTextConfig", "TextToSpeech", "TextToSpeechConfig", "SemanticRouter",
        "SemanticRouterConfig", "Route", "MapEncoding", "MapConfig", "MapLayer", "VideoMessageMaker",
        "VideoMessageMakerConfig", "VLA", "VLAConfig", "Cortex", "CortexConfig", "Memory", "MemoryConfig")},
}

# The public names: the request/response types and errors imported above, then the lazy ones.
__all__ = [
    "MalformedResponseError",
    "ModelClientError",
    "ModelConnectionError",
    "ModelNotFoundError",
    "ModelServerError",
    "ModelTimeoutError",
    "ActionChunk",
    "ChatChunk",
    "ChatMessage",
    "ChatRequest",
    "ChatResponse",
    "Detection2D",
    "DetectionRequest",
    "DetectionResponse",
    "EmbeddingRequest",
    "EmbeddingResponse",
    "ImageData",
    "PolicyObservation",
    "SpeechRequest",
    "SpeechResponse",
    "ToolCall",
    "ToolSpec",
    "TranscriptionRequest",
    "TranscriptionResponse",
]
__all__ += sorted(_LAZY)


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'emos.actors.agents' has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
