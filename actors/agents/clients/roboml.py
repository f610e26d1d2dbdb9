"""RoboMLHTTPClient: models served as nodes on a RoboML server, over HTTP (text streaming)."""
from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from ..errors import MalformedResponseError, ModelServerError
from ..types import ChatChunk, ChatRequest, DetectionRequest
from . import roboml_codec
from .base import ModelClient
from .http_transport import HTTPTransport

__all__ = ["RoboMLHTTPClient"]


class RoboMLHTTPClient(ModelClient):
    """Adds a node for the model (``/add_node``), initializes it with the spec's init params,
    then calls ``/{name}/inference``; ``deinitialize`` removes the node."""

    SUPPORTED_MODELS = tuple(roboml_codec.MODEL_KINDS)
    DEFAULT_PORT = 8000

    def __init__(self, model, host: str = "127.0.0.1", port: int | None = 8000, inference_timeout: float = 30,
                 init_on_activation: bool = True, logging_level: str = "info", **kwargs: Any) -> None:
        super().__init__(model, host=host, port=port, inference_timeout=inference_timeout,
                         init_on_activation=init_on_activation, logging_level=logging_level, **kwargs)
        self._http = HTTPTransport(self.url, timeout=self.inference_timeout, connect_timeout=self.connect_timeout,
                                   context=self._error_context())

    def close(self) -> None:
        self._http.close()

    def _check_connection(self) -> None:
        self._http.request_json("GET", "/")

    def _initialize(self) -> None:
        self._http.request_json("POST", "/add_node", params={"node_name": self.model_name, "node_model": self.model_type})
        self._http.request("POST", f"/{self.model_name}/initialize", json=self.model.get_init_params(),
                           timeout=self.init_timeout or max(self.inference_timeout, 600.0))
        status = self.status()
        if status != "READY":
            raise ModelServerError(f"node {self.model_name!r} is {status} after initialization", status=500,
                                   **self._http.context_for(f"/{self.model_name}/get_status"))

    def status(self) -> str:
        """The node's status on the server: LOADED, INITIALIZING, READY or INITIALIZATION_ERROR."""
        path = f"/{self.model_name}/get_status"
        status = self._http.request_json("GET", path)
        if not isinstance(status, str):
            raise MalformedResponseError("a status string", status, **self._http.context_for(path))
        return status

    def _deinitialize(self) -> None:
        self._http.request("POST", "/remove_node", params={"node_name": self.model_name})

    # ------------------------------------------------------------------ inference
    @property
    def _inference_path(self) -> str:
        return f"/{self.model_name}/inference"

    def _run(self, request: Any) -> Any:
        ctx = self._http.context_for(self._inference_path)
        kind = roboml_codec.kind_of(request, self.model_type, ctx)
        body = self._http.request_json("POST", self._inference_path, json=roboml_codec.build_payload(request, kind))
        return roboml_codec.parse_output(body, kind, self.model.checkpoint, ctx)

    _chat = _speech = _transcribe = _run

    def _other_inference(self, request: Any) -> Any:
        if isinstance(request, DetectionRequest):
            return self._run(request)
        return super()._other_inference(request)

    def _chat_stream(self, request: ChatRequest) -> Iterator[ChatChunk]:
        ctx = self._http.context_for(self._inference_path)
        kind = roboml_codec.kind_of(request, self.model_type, ctx)
        pieces = self._http.stream_text("POST", self._inference_path, json=roboml_codec.build_payload(request, kind))

        def chunks() -> Iterator[ChatChunk]:
            for piece in pieces:
                if piece:
                    yield ChatChunk(content=piece)
            yield ChatChunk(content="", done=True, finish_reason="stop")

        return chunks()
