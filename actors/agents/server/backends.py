"""The local models behind the server: chat responders, embeddings, TTS, STT and detection.

Heavy models load on first use (the server must start fast: the chaos suite restarts it), and
each sits behind a lock because the server runs blocking calls in a thread pool.
"""
from __future__ import annotations

import threading
from typing import Any, Protocol

import numpy as np

from emos.errors import EmosError

from ..types import ChatRequest, ChatResponse
from .responder import ScriptedResponder

__all__ = ["LocalModels", "BackendUnavailable", "ChatBackend", "EMBEDDING_NAMES"]

#: names the packaged sentence embedder answers to (OpenAI/HF style and Ollama style).
EMBEDDING_NAMES = ("all-minilm-l6-v2", "all-MiniLM-L6-v2", "sentence-transformers/all-MiniLM-L6-v2", "all-minilm")
TTS_NAME = "espeak-ng"
# OpenAI voice names have no espeak equivalent; they all map to the default English voice.
OPENAI_VOICES = {"alloy", "ash", "ballad", "coral", "echo", "fable", "nova", "onyx", "sage", "shimmer", "verse"}


class BackendUnavailable(EmosError, RuntimeError):
    """A capability this server cannot provide here (answered with HTTP 501)."""


class ChatBackend(Protocol):
    def respond(self, request: ChatRequest, model: str) -> ChatResponse: ...
    def stream(self, request: ChatRequest, model: str): ...


def check_wav(audio: bytes) -> None:
    """Raise ValueError unless ``audio`` parses as a WAV file. Python's wave module answers
    bytes that only start like one with wave.Error, EOFError, struct.error or even a bare
    RuntimeError; any of them means the client sent something else."""
    from ..local.audio import read_wav

    try:
        read_wav(bytes(audio))
    except ValueError as exc:
        raise ValueError(f"audio could not be decoded (expected a WAV file): {exc}") from None
    except Exception as exc:  # noqa: BLE001 - untrusted bytes: every parse failure is the input's
        raise ValueError(f"audio could not be decoded (expected a WAV file): {type(exc).__name__} {exc}".rstrip()) from None


class LocalModels:
    def __init__(self, script: Any = None, gguf: str | None = None, extra_models: tuple[str, ...] = ()) -> None:
        scripted = ScriptedResponder(script)
        self.default_chat = scripted.name
        self.chat: dict[str, ChatBackend] = {scripted.name: scripted}
        for alias in (*scripted.aliases, *extra_models):
            self.chat[alias] = scripted
        if gguf:
            from .llama_backend import LlamaCppResponder

            llama = LlamaCppResponder(gguf)
            self.chat[llama.name] = llama
            self.default_chat = llama.name
        self._lock = threading.Lock()
        self._embedder: Any = None
        self._tts: Any = None
        self._stt: Any = None
        self._detector: Any = None

    # ------------------------------------------------------------------ registry
    def chat_backend(self, name: str) -> ChatBackend | None:
        if name is not None and not isinstance(name, str):  # a JSON list or object: no such model
            return None
        return self.chat.get(name or self.default_chat)

    def all_names(self) -> list[str]:
        return [*self.chat, EMBEDDING_NAMES[0], TTS_NAME]

    def has(self, name: object) -> bool:
        """Whether ``name`` names a local model (any value from a request body may be asked)."""
        if not isinstance(name, str):
            return False
        return name in self.chat or name in EMBEDDING_NAMES or name == TTS_NAME

    # ------------------------------------------------------------------ embeddings
    def embed(self, texts: list[str]) -> np.ndarray:
        with self._lock:
            if self._embedder is None:
                try:
                    from ..local.embeddings import SentenceEmbedder
                except ImportError as exc:
                    raise BackendUnavailable(f"no local embedding model: {exc}") from None
                self._embedder = SentenceEmbedder()
        return self._embedder.embed(texts)

    # ------------------------------------------------------------------ speech
    def synthesize(self, text: str, voice: str | None = None, speed: float | None = None) -> bytes:
        with self._lock:
            if self._tts is None:
                try:
                    from ..local.tts import EspeakTTS

                    self._tts = EspeakTTS()
                except (ImportError, FileNotFoundError) as exc:
                    raise BackendUnavailable(f"no local text-to-speech: {exc}") from None
        espeak_voice = None if (voice is None or voice in OPENAI_VOICES) else voice
        wpm = int(round(175 * speed)) if speed else None  # espeak's normal rate is 175 words/min
        return self._tts.synthesize(text, voice=espeak_voice, speed_wpm=wpm)

    def transcribe(self, audio: bytes, language: str | None = None) -> str:
        """The words in ``audio`` (WAV bytes); ValueError if they are not a WAV file."""
        if language is not None and not isinstance(language, str):
            raise ValueError(f"language must be a string, got {type(language).__name__}")
        if language and not language.lower().startswith("en"):
            raise BackendUnavailable(f"the local speech-to-text model is English only; language {language!r} is unavailable")
        with self._lock:
            if self._stt is None:
                try:
                    from ..local.stt import PocketSphinxSTT

                    self._stt = PocketSphinxSTT()
                except ImportError as exc:
                    raise BackendUnavailable(f"no packaged speech-to-text model is installed here ({exc})") from None
        check_wav(audio)
        with self._lock:
            try:
                return str(self._stt.transcribe(audio))
            except (ValueError, TypeError) as exc:
                raise ValueError(f"audio could not be decoded (expected a WAV file): {exc}") from None

    # ------------------------------------------------------------------ detection
    def detect(self, image: np.ndarray, threshold: float) -> dict[str, Any]:
        """People and faces with OpenCV's packaged detectors (the local Vision model)."""
        found = self._detections(image, threshold)
        return {"bboxes": [list(d.box) for d in found], "labels": [d.label for d in found],
                "scores": [float(d.score) for d in found]}

    def ground(self, image: np.ndarray, description: str, threshold: float = 0.5) -> list[list[float]]:
        """Boxes (xyxy, best first) of what ``description`` names, by the local detector
        (``local/grounding.py``): the stand-in for a planning VLM's grounding."""
        from ..local.grounding import ground

        return ground(self._detections(image, threshold), description)

    def _detections(self, image: np.ndarray, threshold: float) -> list[Any]:
        with self._lock:
            if self._detector is None:
                try:
                    from ..local.vision import LocalDetector

                    # Threshold 0 here: each request filters with its own threshold below.
                    self._detector = LocalDetector(threshold=0.0)
                except ImportError as exc:
                    raise BackendUnavailable(f"no local detector: {exc}") from None
        return [d for d in self._detector.detect(image) if d.score >= threshold]
