"""Typed requests and responses shared by every model client and the local model server.

Clients never hand untyped dicts to components: a chat reply is a :class:`ChatResponse`, a
streamed piece a :class:`ChatChunk`, a tool call a :class:`ToolCall` whose ``arguments`` is
always a decoded ``dict`` (OpenAI sends a JSON *string*; the original assumed a dict and broke).

Images travel as :class:`ImageData` (bytes plus a MIME type sniffed from magic bytes), so an
OpenAI data URL always says ``image/png`` for a PNG and ``image/jpeg`` for a JPEG. numpy arrays
are encoded to PNG with the standard library only (zlib), so this module needs no Pillow.
"""
from __future__ import annotations

import base64
import json
import struct
import zlib
from typing import Any

import attrs
import numpy as np

from emos.config import validators as V

from .errors import MalformedResponseError

__all__ = [
    "ImageData",
    "ToolCall",
    "ToolSpec",
    "ChatMessage",
    "ChatRequest",
    "ChatResponse",
    "ChatChunk",
    "EmbeddingRequest",
    "EmbeddingResponse",
    "SpeechRequest",
    "SpeechResponse",
    "TranscriptionRequest",
    "TranscriptionResponse",
    "DetectionRequest",
    "Detection2D",
    "DetectionResponse",
    "PolicyObservation",
    "ActionChunk",
    "decode_tool_arguments",
    "sniff_image_mime",
    "encode_png",
]

ROLES = ("system", "user", "assistant", "tool")


# --------------------------------------------------------------------------- images


def sniff_image_mime(data: bytes) -> str | None:
    """MIME type of an encoded image from its magic bytes, or None if not PNG/JPEG/WebP/GIF."""
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return "image/png"
    if data[:3] == b"\xff\xd8\xff":
        return "image/jpeg"
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return "image/webp"
    if data[:6] in (b"GIF87a", b"GIF89a"):
        return "image/gif"
    return None


def _png_chunk(kind: bytes, payload: bytes) -> bytes:
    crc = zlib.crc32(kind + payload) & 0xFFFFFFFF
    return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", crc)


def encode_png(array: np.ndarray, compression: int = 6) -> bytes:
    """Encode an HxW (grey), HxWx3 (RGB) or HxWx4 (RGBA) array as PNG.

    Float arrays are taken as 0..1 and scaled; other integer types are clipped to 0..255.
    """
    arr = np.asarray(array)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (3, 4)) or arr.size == 0:
        raise ValueError(f"image array: expected HxW, HxWx3 or HxWx4, got shape {arr.shape}")
    if arr.dtype != np.uint8:
        if np.issubdtype(arr.dtype, np.floating):
            arr = np.nan_to_num(arr) * 255.0
        arr = np.clip(arr, 0, 255).astype(np.uint8)
    height, width = arr.shape[:2]
    color_type = 0 if arr.ndim == 2 else {3: 2, 4: 6}[arr.shape[2]]
    # Each scanline is prefixed with filter type 0 (None); vectorized via a prepended column.
    rows = np.ascontiguousarray(arr).reshape(height, -1)
    raw = np.concatenate([np.zeros((height, 1), np.uint8), rows], axis=1).tobytes()
    header = struct.pack(">IIBBBBB", width, height, 8, color_type, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + _png_chunk(b"IHDR", header)
        + _png_chunk(b"IDAT", zlib.compress(raw, compression))
        + _png_chunk(b"IEND", b"")
    )


@attrs.define(frozen=True)
class ImageData:
    """An encoded image: raw bytes and their MIME type."""

    data: bytes = attrs.field(validator=attrs.validators.instance_of(bytes), repr=lambda b: f"<{len(b)} bytes>")
    mime_type: str = attrs.field(validator=attrs.validators.in_(("image/png", "image/jpeg", "image/webp", "image/gif")))

    @classmethod
    def from_bytes(cls, data: bytes) -> ImageData:
        mime = sniff_image_mime(data)
        if mime is None:
            raise ValueError(
                f"image bytes: expected PNG, JPEG, WebP or GIF (by magic bytes), got {bytes(data[:8])!r}..."
            )
        return cls(bytes(data), mime)

    @classmethod
    def from_array(cls, array: np.ndarray) -> ImageData:
        return cls(encode_png(array), "image/png")

    @classmethod
    def from_base64(cls, text: str) -> ImageData:
        """From plain base64 or a ``data:image/...;base64,`` URL."""
        if text.startswith("data:"):
            text = text.split(",", 1)[1] if "," in text else ""
        try:
            raw = base64.b64decode(text, validate=True)
        except (ValueError, TypeError) as exc:
            raise ValueError(f"image base64: not valid base64 ({exc})") from None
        return cls.from_bytes(raw)

    @classmethod
    def coerce(cls, value: Any) -> ImageData:
        """Accept ImageData, encoded bytes, a numpy array or a base64/data-URL string."""
        if isinstance(value, ImageData):
            return value
        if isinstance(value, (bytes, bytearray, memoryview)):
            return cls.from_bytes(bytes(value))
        if isinstance(value, np.ndarray):
            return cls.from_array(value)
        if isinstance(value, str):
            return cls.from_base64(value)
        raise TypeError(f"image: expected ImageData, bytes, numpy array or base64 str, got {type(value).__name__}")

    def to_base64(self) -> str:
        return base64.b64encode(self.data).decode("ascii")

    def to_data_url(self) -> str:
        return f"data:{self.mime_type};base64,{self.to_base64()}"


def _images(value: Any) -> list[ImageData]:
    if value is None:
        return []
    if isinstance(value, (np.ndarray, bytes, str, ImageData)):
        value = [value]
    return [ImageData.coerce(v) for v in value]


# --------------------------------------------------------------------------- tools


def decode_tool_arguments(raw: Any, *, client: str | None = None, model: str | None = None, url: str | None = None) -> dict:
    """Tool-call arguments as a dict, whatever the server sent.

    OpenAI sends a JSON string (possibly empty for a tool without parameters), Ollama a JSON
    object. Anything else is a malformed response, not a crash further down the line.
    """
    if raw is None or raw == "":
        return {}
    if isinstance(raw, dict):
        return raw
    if isinstance(raw, (str, bytes)):
        try:
            value = json.loads(raw)
        except ValueError:
            raise MalformedResponseError(
                "tool-call arguments as a JSON object string", raw, client=client, model=model, url=url
            ) from None
        if isinstance(value, dict):
            return value
        raise MalformedResponseError("tool-call arguments as a JSON object", raw, client=client, model=model, url=url)
    raise MalformedResponseError("tool-call arguments as a JSON object", raw, client=client, model=model, url=url)


def _dict_of_str_keys(instance, attribute, value) -> None:
    if not isinstance(value, dict):
        raise TypeError(f"{type(instance).__name__}.{attribute.name}: expected dict, got {type(value).__name__}")


@attrs.define(frozen=True)
class ToolCall:
    """A call the model asks us to make. ``arguments`` is always a decoded dict."""

    id: str = attrs.field(converter=str)
    name: str = attrs.field(validator=attrs.validators.instance_of(str))
    arguments: dict = attrs.field(factory=dict, validator=_dict_of_str_keys)

    def __attrs_post_init__(self) -> None:
        if not self.name:
            raise ValueError("ToolCall.name: expected a non-empty tool name")


def _json_schema(instance, attribute, value) -> None:
    if not isinstance(value, dict):
        raise TypeError(f"ToolSpec.parameters: expected a JSON-schema dict, got {type(value).__name__}")
    if value and value.get("type", "object") != "object":
        raise ValueError(f"ToolSpec.parameters: expected a JSON schema of type 'object', got {value.get('type')!r}")


@attrs.define(frozen=True)
class ToolSpec:
    """A tool offered to the model: name, description and a JSON-schema for its arguments."""

    name: str = attrs.field(validator=attrs.validators.and_(attrs.validators.instance_of(str), attrs.validators.min_len(1)))
    description: str = attrs.field(default="", validator=attrs.validators.instance_of(str))
    parameters: dict = attrs.field(factory=lambda: {"type": "object", "properties": {}}, validator=_json_schema)

    def to_openai(self) -> dict:
        """The ``tools`` entry both OpenAI and Ollama expect."""
        return {
            "type": "function",
            "function": {"name": self.name, "description": self.description, "parameters": self.parameters},
        }


def _tool_calls(value: Any) -> list[ToolCall]:
    out = []
    for item in value or []:
        if isinstance(item, ToolCall):
            out.append(item)
        elif isinstance(item, dict):
            out.append(ToolCall(id=item.get("id", ""), name=item["name"], arguments=decode_tool_arguments(item.get("arguments"))))
        else:
            raise TypeError(f"tool_calls: expected ToolCall or dict items, got {type(item).__name__}")
    return out


# --------------------------------------------------------------------------- chat


@attrs.define
class ChatMessage:
    """One chat turn. ``content`` may be None for an assistant turn that only calls tools."""

    role: str = attrs.field(validator=attrs.validators.in_(ROLES))
    content: str | None = attrs.field(default=None, validator=attrs.validators.optional(attrs.validators.instance_of(str)))
    images: list[ImageData] = attrs.field(factory=list, converter=_images)
    tool_calls: list[ToolCall] = attrs.field(factory=list, converter=_tool_calls)
    tool_call_id: str | None = attrs.field(default=None)
    name: str | None = attrs.field(default=None)

    def text_only(self) -> ChatMessage:
        """A copy without images: what chat history keeps (images would grow it unboundedly)."""
        return attrs.evolve(self, images=[])


def _messages(value: Any) -> list[ChatMessage]:
    out = []
    for item in value:
        if isinstance(item, ChatMessage):
            out.append(item)
        elif isinstance(item, dict):
            out.append(ChatMessage(**item))
        else:
            raise TypeError(f"ChatRequest.messages: expected ChatMessage or dict items, got {type(item).__name__}")
    return out


def _tools(value: Any) -> list[ToolSpec]:
    out = []
    for item in value or []:
        if isinstance(item, ToolSpec):
            out.append(item)
        elif isinstance(item, dict):
            fn = item.get("function", item)
            out.append(ToolSpec(name=fn["name"], description=fn.get("description", ""), parameters=fn.get("parameters", {})))
        else:
            raise TypeError(f"ChatRequest.tools: expected ToolSpec or dict items, got {type(item).__name__}")
    return out


@attrs.define
class ChatRequest:
    """A chat completion request; ``options`` carries backend-specific extras."""

    messages: list[ChatMessage] = attrs.field(converter=_messages)
    tools: list[ToolSpec] = attrs.field(factory=list, converter=_tools)
    stream: bool = attrs.field(default=False, validator=attrs.validators.instance_of(bool))
    temperature: float | None = attrs.field(default=None, validator=V.number(ge=0.0, le=2.0, allow_none=True))
    max_tokens: int | None = attrs.field(default=None, validator=V.number(ge=1, le=10**7, allow_none=True))
    options: dict = attrs.field(factory=dict, validator=_dict_of_str_keys)
    #: the VLM planning task ("pointing", "affordance", "trajectory", "grounding", "general") for
    #: servers whose planning models take it (RoboML's PlanningInput); other protocols ignore it
    task: str | None = attrs.field(default=None, validator=attrs.validators.optional(attrs.validators.instance_of(str)))

    def __attrs_post_init__(self) -> None:
        if not self.messages:
            raise ValueError("ChatRequest.messages: expected at least one message")


@attrs.define
class ChatResponse:
    """A complete chat reply."""

    message: ChatMessage
    finish_reason: str | None = None
    usage: dict | None = None
    model: str = ""


@attrs.define
class ChatChunk:
    """One streamed piece. ``content`` is never None (servers send null deltas; we use "")."""

    content: str = attrs.field(default="", converter=lambda v: "" if v is None else str(v))
    tool_calls: list[ToolCall] = attrs.field(factory=list, converter=_tool_calls)
    done: bool = False
    finish_reason: str | None = None
    usage: dict | None = None


# --------------------------------------------------------------------------- embeddings


@attrs.define
class EmbeddingRequest:
    texts: list[str] = attrs.field(converter=lambda v: [v] if isinstance(v, str) else list(v))

    def __attrs_post_init__(self) -> None:
        if not self.texts or not all(isinstance(t, str) for t in self.texts):
            raise ValueError("EmbeddingRequest.texts: expected a non-empty list of strings")


@attrs.define
class EmbeddingResponse:
    """``embeddings`` is an n x d float32 array, one row per input text."""

    embeddings: np.ndarray = attrs.field(converter=lambda v: np.asarray(v, dtype=np.float32))
    model: str = ""
    usage: dict | None = None

    def __attrs_post_init__(self) -> None:
        if self.embeddings.ndim != 2:
            raise ValueError(f"EmbeddingResponse.embeddings: expected an n x d array, got shape {self.embeddings.shape}")


# --------------------------------------------------------------------------- speech

AUDIO_FORMATS = ("wav", "mp3", "opus", "aac", "flac", "pcm")
AUDIO_MIME = {
    "wav": "audio/wav",
    "mp3": "audio/mpeg",
    "opus": "audio/ogg",
    "aac": "audio/aac",
    "flac": "audio/flac",
    "pcm": "audio/L16",
}


@attrs.define
class SpeechRequest:
    """Text to synthesize. ``speed`` follows OpenAI (0.25..4.0, 1.0 = normal)."""

    text: str = attrs.field(validator=attrs.validators.and_(attrs.validators.instance_of(str), attrs.validators.min_len(1)))
    voice: str | None = None
    speed: float | None = attrs.field(default=None, validator=V.number(ge=0.25, le=4.0, allow_none=True))
    response_format: str = attrs.field(default="wav", validator=attrs.validators.in_(AUDIO_FORMATS))


@attrs.define
class SpeechResponse:
    audio: bytes = attrs.field(repr=lambda b: f"<{len(b)} bytes>")
    mime_type: str = "audio/wav"


@attrs.define
class TranscriptionRequest:
    """Audio to transcribe: encoded file bytes (WAV etc.) or raw PCM as a numpy array."""

    audio: bytes = attrs.field(repr=lambda b: f"<{len(b)} bytes>", validator=attrs.validators.instance_of(bytes))
    filename: str = "audio.wav"
    language: str | None = None
    temperature: float | None = attrs.field(default=None, validator=V.number(ge=0.0, le=1.0, allow_none=True))
    prompt: str | None = None


@attrs.define
class TranscriptionResponse:
    text: str
    language: str | None = None


# --------------------------------------------------------------------------- detection


@attrs.define
class DetectionRequest:
    """Images to run a detector on; one :class:`Detection2D` per image comes back."""

    images: list[ImageData] = attrs.field(converter=_images)
    threshold: float = attrs.field(default=0.5, validator=V.number(ge=0, le=1))
    labels_to_track: list[str] | None = None

    def __attrs_post_init__(self) -> None:
        if not self.images:
            raise ValueError("DetectionRequest.images: expected at least one image")


@attrs.define
class Detection2D:
    """Detections in one image: ``boxes`` is N x 4 (x1, y1, x2, y2) pixels, ``scores`` N."""

    boxes: np.ndarray = attrs.field(converter=lambda v: np.asarray(v, dtype=np.float64).reshape(-1, 4))
    labels: list[str] = attrs.field(factory=list, converter=lambda v: [str(x) for x in v])
    scores: np.ndarray = attrs.field(factory=lambda: np.zeros(0), converter=lambda v: np.asarray(v, dtype=np.float64).reshape(-1))

    def __attrs_post_init__(self) -> None:
        if not (len(self.boxes) == len(self.labels) == len(self.scores)):
            raise ValueError(
                f"Detection2D: boxes ({len(self.boxes)}), labels ({len(self.labels)}) and scores ({len(self.scores)}) differ in length"
            )


@attrs.define
class DetectionResponse:
    detections: list[Detection2D]


# --------------------------------------------------------------------------- VLA policies


@attrs.define
class PolicyObservation:
    """One robot observation for a VLA policy: joint values by name, camera images (HxWx3
    uint8 arrays) by name and the ``task`` instruction, keyed as the policy's dataset expects."""

    observation: dict = attrs.field(validator=_dict_of_str_keys)
    timestep: int = attrs.field(default=0, validator=attrs.validators.instance_of(int))
    must_go: bool = True
    timestamp: float | None = None


@attrs.define
class ActionChunk:
    """Actions predicted for consecutive timesteps: ``actions`` is (t, a) float32."""

    timesteps: np.ndarray = attrs.field(converter=lambda v: np.asarray(v, dtype=np.int64).reshape(-1))
    timestamps: np.ndarray = attrs.field(converter=lambda v: np.asarray(v, dtype=np.float64).reshape(-1))
    actions: np.ndarray = attrs.field(converter=lambda v: np.asarray(v, dtype=np.float32))

    def __attrs_post_init__(self) -> None:
        if self.actions.ndim != 2 or not (len(self.actions) == len(self.timesteps) == len(self.timestamps)):
            raise ValueError(
                f"ActionChunk: expected (t, a) actions with t timesteps and timestamps, got actions {self.actions.shape}, "
                f"{len(self.timesteps)} timesteps, {len(self.timestamps)} timestamps"
            )
