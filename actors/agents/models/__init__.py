"""Model specifications: what to load, independent of where it is served.

Each spec is validated on construction, carries ``get_init_params()`` (the platform init
payload) and ``to_dict()``; :func:`model_from_dict` rebuilds one in another process.
"""
from .base import MODEL_TYPES, Model, model_from_dict
from .generic import GenericLLM, GenericMLLM, GenericSTT, GenericTTS
from .lerobot import LeRobotPolicy, features_from_dataset_info
from .ollama import OllamaModel
from .speech import Bark, MeloTTS, SpeechT5, Whisper
from .transformers import RoboBrain2, TransformersLLM, TransformersMLLM
from .vision import VisionModel

__all__ = [
    "Model",
    "MODEL_TYPES",
    "model_from_dict",
    "GenericLLM",
    "GenericMLLM",
    "GenericTTS",
    "GenericSTT",
    "OllamaModel",
    "TransformersLLM",
    "TransformersMLLM",
    "LeRobotPolicy",
    "features_from_dataset_info",
    "RoboBrain2",
    "Whisper",
    "SpeechT5",
    "Bark",
    "MeloTTS",
    "VisionModel",
]
