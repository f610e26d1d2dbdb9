"""RoboML's model-node protocol, server side: nodes are added, initialized, queried, removed.

Shared by the HTTP/WebSocket routes and the RESP server, exactly as RoboML shares one node
implementation between its Ray HTTP app and its RESP server. Inference payloads follow RoboML's
input models: chat ``query`` is a list of ``{role, content}`` messages (plus base64 ``images``),
TTS ``query`` is text, STT ``query`` is base64 audio, detection takes base64 ``images``.
"""
from __future__ import annotations

import base64
import threading
from collections.abc import Iterator
from typing import Any

import numpy as np

from emos.errors import EmosError

from ..types import ChatMessage, ChatRequest, ImageData
from .backends import BackendUnavailable, LocalModels

__all__ = ["RoboMLNodes", "NodeError", "STREAM_END"]

#: sent after the last streamed text piece on the websocket (RoboML's terminator).
STREAM_END = "<<Response Ended>>"

KINDS = {
    "TransformersLLM": "chat",
    "TransformersMLLM": "chat",
    "RoboBrain2": "chat",
    "Whisper": "stt",
    "SpeechT5": "tts",
    "Bark": "tts",
    "MeloTTS": "tts",
    "VisionModel": "detect",
}
RESERVED = {"v1", "api", "add_node", "remove_node"}
#: planning tasks the local server answers with its detector (see ``_planning``)
PLANNING_TASKS = ("grounding", "pointing")


class NodeError(EmosError):
    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


def _decode_image(value: Any) -> np.ndarray:
    try:
        import cv2  # detection only; cv2 ships with the agents extra
    except ImportError:
        raise NodeError(501, "decoding images needs OpenCV: pip install 'emos[agents]'") from None

    raw = value if isinstance(value, bytes) else base64.b64decode(str(value).split(",")[-1])
    image = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        raise NodeError(400, "images: expected base64-encoded PNG/JPEG images")
    return np.ascontiguousarray(image[:, :, ::-1])  # OpenCV decodes BGR; detectors take RGB


class RoboMLNodes:
    def __init__(self, models: LocalModels) -> None:
        self.models = models
        self.nodes: dict[str, dict[str, Any]] = {}
        self._lock = threading.Lock()

    def add_node(self, name: str, model_type: str) -> tuple[int, dict]:
        if not name or name in RESERVED or "/" in name:
            raise NodeError(400, f"invalid node name {name!r}")
        with self._lock:
            if name in self.nodes:
                return 200, {"node": name, "warning": f"Name duplication. A model with name {name} already exists."}
            if model_type not in KINDS:
                raise NodeError(400, f"{model_type} is not a supported model type on this server; expected one of {sorted(KINDS)}")
            self.nodes[name] = {"type": model_type, "kind": KINDS[model_type], "status": "LOADED", "params": {}}
        return 201, {"node": name}

    def remove_node(self, name: str) -> dict:
        with self._lock:
            if self.nodes.pop(name, None) is None:
                raise NodeError(400, f"Node with name {name} does not exist.")
        return {"node": name}

    def _node(self, name: str) -> dict[str, Any]:
        node = self.nodes.get(name)
        if node is None:
            raise NodeError(404, f"Node with name {name} does not exist.")
        return node

    def initialize(self, name: str, params: dict | None) -> None:
        node = self._node(name)
        if params is not None and not isinstance(params, dict):
            raise NodeError(400, f"initialize: expected an object of parameters, got {type(params).__name__}")
        node["params"] = dict(params or {})
        node["status"] = "READY"

    def status(self, name: str) -> str:
        return self._node(name)["status"]

    def inference(self, name: str, data: dict) -> dict | Iterator[str]:
        """The node's ``{"output": ...}`` result, or an iterator of text pieces if streaming."""
        node = self._node(name)
        if node["status"] != "READY":
            raise NodeError(500, "Inference called before initialization")
        if not isinstance(data, dict):
            raise NodeError(400, "inference input: expected an object")
        try:
            return getattr(self, f"_{node['kind']}")(node, data)
        except BackendUnavailable as exc:
            raise NodeError(501, str(exc)) from None
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise NodeError(400, f"invalid inference input: {exc}") from None
        except RecursionError:
            raise NodeError(400, "invalid inference input: nested too deeply") from None

    def _chat(self, node: dict, data: dict) -> dict | Iterator[str]:
        query = data["query"]
        if not isinstance(query, list) or not query:
            raise ValueError("'query' must be a non-empty list of {role, content} messages")
        task = data.get("task")
        if task not in (None, "general"):
            return self._planning(node, task, query, data)
        messages = [ChatMessage(role=m["role"], content=m.get("content")) for m in query]
        images = [ImageData.coerce(i) for i in data.get("images") or []]
        if images:  # RoboML attaches the images to the last user turn
            messages[-1] = ChatMessage(role=messages[-1].role, content=messages[-1].content, images=images)
        request = ChatRequest(messages=messages, temperature=data.get("temperature"),
                              max_tokens=data.get("max_new_tokens"), stream=bool(data.get("stream")))
        backend = self.models.chat_backend("")
        assert backend is not None  # "" names the default chat model, which LocalModels always has
        if request.stream:
            return (c.content for c in backend.stream(request, node["type"]) if c.content)
        return {"output": backend.respond(request, node["type"]).message.content or ""}

    def _tts(self, node: dict, data: dict) -> dict:
        text = data["query"]
        if not isinstance(text, str) or not text.strip():
            raise ValueError("'query' must be non-empty text")
        # RoboML voices (SpeechT5 'clb', Bark presets) have no espeak equivalent: default voice.
        audio = self.models.synthesize(text)
        return {"output": audio if data.get("get_bytes") else base64.b64encode(audio).decode()}

    def _stt(self, node: dict, data: dict) -> dict:
        query = data["query"]
        audio = query if isinstance(query, bytes) else base64.b64decode(query)
        return {"output": self.models.transcribe(audio, node["params"].get("language"))}

    def _detect(self, node: dict, data: dict) -> dict:
        images = data["images"]
        if not isinstance(images, list) or not images:
            raise ValueError("'images' must be a non-empty list")
        threshold = float(data.get("threshold", 0.5))
        return {"output": [self.models.detect(_decode_image(img), threshold) for img in images]}

    def _planning(self, node: dict, task: Any, query: list, data: dict) -> dict:
        """A planning task (RoboML's PlanningInput), answered in its structure as RoboML's
        RoboBrain2 node does: grounding boxes ``[[x1, y1, x2, y2], ...]``, pointing points
        ``[[x, y], ...]``. The local detector grounds the description (``local/grounding.py``)."""
        if task not in PLANNING_TASKS:
            raise NodeError(501, f"task {task!r}: the local model server answers the planning tasks {PLANNING_TASKS} "
                                 "(with its detector); others need a planning model such as RoboBrain 2.0 on RoboML")
        if data.get("stream"):
            raise ValueError(f"task {task!r}: a planning task answers with a structure, it cannot stream")
        images = data.get("images") or []
        if not isinstance(images, list) or not images:
            raise ValueError(f"task {task!r} needs an image in 'images'")
        last = query[-1]
        description = last.get("content") if isinstance(last, dict) else None
        if not isinstance(description, str) or not description.strip():
            raise ValueError(f"task {task!r}: the last message must hold the description as text")
        boxes = self.models.ground(_decode_image(images[-1]), description)
        if task == "pointing":
            from ..local.grounding import box_centres

            return {"output": box_centres(boxes)}
        return {"output": boxes}
