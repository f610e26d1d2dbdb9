"""LeRobotClient: VLA policies on LeRobot's async policy server (gRPC ``transport.AsyncInference``).

Flow, as LeRobot's own robot client does it: ``Ready`` (connection check and state reset),
``SendPolicyInstructions`` (pickled ``RemotePolicyConfig``: which checkpoint, which features),
then per step ``SendObservations`` (a client stream of pickled ``TimedObservation`` chunks) and
``GetActions`` (pickled list of ``TimedAction``). See :mod:`.lerobot_wire` for the encoding and
why replies are unpickled through an allow-list.
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..errors import MalformedResponseError, ModelConnectionError, ModelServerError, ModelTimeoutError
from ..types import ActionChunk, PolicyObservation
from . import lerobot_wire as wire
from .base import ModelClient

__all__ = ["LeRobotClient"]

_MAX_MESSAGE = 64 * 1024 * 1024


def _grpc() -> Any:
    return wire.import_grpc()


def _to_numpy(action: Any) -> np.ndarray:
    if hasattr(action, "detach"):  # a torch tensor
        action = action.detach().cpu().numpy()
    return np.asarray(action, dtype=np.float32).reshape(-1)


class LeRobotClient(ModelClient):
    SUPPORTED_MODELS = ("LeRobotPolicy",)
    DEFAULT_PORT = 8080

    def __init__(self, model, host: str = "127.0.0.1", port: int | None = 8080, inference_timeout: float = 30,
                 init_on_activation: bool = True, logging_level: str = "info", **kwargs: Any) -> None:
        super().__init__(model, host=host, port=port, inference_timeout=inference_timeout,
                         init_on_activation=init_on_activation, logging_level=logging_level, **kwargs)
        self._channel: Any = None

    @property
    def url(self) -> str:
        return f"grpc://{self.host}:{self.port}"

    def close(self) -> None:
        if self._channel is not None:
            self._channel.close()
            self._channel = None

    def _call(self, method: str, kind: str, request: Any, timeout: float) -> Any:
        grpc = _grpc()
        if self._channel is None:
            self._channel = grpc.insecure_channel(
                f"{self.host}:{self.port}",
                options=[("grpc.max_send_message_length", _MAX_MESSAGE), ("grpc.max_receive_message_length", _MAX_MESSAGE)],
            )
        path = f"/{wire.SERVICE}/{method}"
        stub = getattr(self._channel, kind)(path, request_serializer=None, response_deserializer=None)
        ctx = self._error_context(f"{self.url}{path}")
        try:
            return stub(request, timeout=timeout)
        except grpc.RpcError as exc:
            code, details = exc.code(), exc.details() or ""
            if code == grpc.StatusCode.UNAVAILABLE:
                raise ModelConnectionError(f"cannot reach the policy server ({details})", **ctx) from None
            if code == grpc.StatusCode.DEADLINE_EXCEEDED:
                raise ModelTimeoutError(f"{method} did not finish within {timeout:.1f}s", **ctx) from None
            raise ModelServerError(f"{method} failed with gRPC {code.name}", status=code.value[0], body=details, **ctx) from None

    # ------------------------------------------------------------------ lifecycle
    def _check_connection(self) -> None:
        self._call("Ready", "unary_unary", b"", self.connect_timeout)

    def _initialize(self) -> None:
        params = self.model.get_init_params()
        if not params["features"]:
            raise ValueError(
                f"LeRobotPolicy {self.model_name!r} has no features: give dataset_info_file or let the VLA "
                "component build them from its config before initializing"
            )
        config = wire.RemotePolicyConfig(
            policy_type=params["policy_type"], pretrained_name_or_path=params["checkpoint"],
            lerobot_features=params["features"], actions_per_chunk=params["actions_per_chunk"], device=params["device"],
        )
        self._call("Ready", "unary_unary", b"", self.connect_timeout)
        self._call("SendPolicyInstructions", "unary_unary", wire.encode_bytes_message(wire.dumps_wire(config)),
                   self.init_timeout or max(self.inference_timeout, 600.0))

    def _deinitialize(self) -> None:
        # The server has no unload call; Ready resets its per-client state, as LeRobot's client does.
        self._call("Ready", "unary_unary", b"", self.connect_timeout)

    # ------------------------------------------------------------------ inference
    def send_observation(self, observation: PolicyObservation) -> None:
        timed = wire.TimedObservation(
            timestamp=observation.timestamp if observation.timestamp is not None else time.time(),
            timestep=observation.timestep, observation=dict(observation.observation), must_go=observation.must_go,
        )
        payload = wire.dumps_wire(timed)
        self._call("SendObservations", "stream_unary", wire.chunk_payload(payload), self.inference_timeout)

    def receive_actions(self, timeout: float | None = None) -> ActionChunk | None:
        """The server's latest action chunk, or None when it has none yet."""
        reply = self._call("GetActions", "unary_unary", b"", timeout or self.inference_timeout)
        ctx = self._error_context(f"{self.url}/{wire.SERVICE}/GetActions")
        try:
            data = wire.decode_fields(reply).get(1, b"")
        except ValueError as exc:
            raise MalformedResponseError("an Actions protobuf message", str(exc), **ctx) from None
        if not data:
            return None
        try:
            timed = wire.loads_wire(data)
        except Exception as exc:  # any unpickling failure is a protocol violation, typed as such
            raise MalformedResponseError("a pickled list of TimedAction", f"{type(exc).__name__}: {exc}", **ctx) from None
        if not isinstance(timed, list) or not all(isinstance(a, wire.TimedAction) for a in timed):
            raise MalformedResponseError("a list of TimedAction", type(timed).__name__, **ctx)
        if not timed:
            return None
        actions = np.stack([_to_numpy(a.action) for a in timed])
        return ActionChunk(timesteps=[a.timestep for a in timed], timestamps=[a.timestamp for a in timed], actions=actions)

    def _other_inference(self, request: Any) -> Any:
        if not isinstance(request, PolicyObservation):
            return super()._other_inference(request)
        self.send_observation(request)
        return self.receive_actions()
