"""A stand-in LeRobot async policy server (gRPC ``transport.AsyncInference``) for tests.

It speaks the real wire protocol (see :mod:`..clients.lerobot_wire`) but runs a trivial,
deterministic policy: every action of a chunk holds the observed joint positions, in the
order of ``observation.state.names`` from the policy setup. That is what a VLA component
needs to be tested end to end without a GPU or model weights.
"""
from __future__ import annotations

import io
import queue
import threading
import time
from concurrent import futures
from typing import Any

from ..clients import lerobot_wire as wire

__all__ = ["HoldPositionPolicyServer"]

FPS = 30.0


class HoldPositionPolicyServer:
    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        grpc = wire.import_grpc()
        self._grpc = grpc
        self.config: wire.RemotePolicyConfig | None = None
        self.observations: queue.Queue = queue.Queue(maxsize=1)
        self.received = 0
        self._lock = threading.Lock()
        handlers: dict[str, Any] = {
            "Ready": grpc.unary_unary_rpc_method_handler(self._ready),
            "SendPolicyInstructions": grpc.unary_unary_rpc_method_handler(self._setup),
            "SendObservations": grpc.stream_unary_rpc_method_handler(self._observations),
            "GetActions": grpc.unary_unary_rpc_method_handler(self._get_actions),
        }
        self.server = grpc.server(futures.ThreadPoolExecutor(max_workers=4), options=[
            ("grpc.max_receive_message_length", 64 * 1024 * 1024), ("grpc.max_send_message_length", 64 * 1024 * 1024),
            # gRPC shares ports by default (SO_REUSEPORT): a second server on a taken port would
            # start "fine" and get half the connections. Bind exclusively.
            ("grpc.so_reuseport", 0)])
        self.server.add_generic_rpc_handlers((grpc.method_handlers_generic_handler(wire.SERVICE, handlers),))
        try:
            self.port = self.server.add_insecure_port(f"{host}:{port}")
        except RuntimeError as exc:  # grpc >= 1.53 raises "Failed to bind to address ..."
            raise OSError(str(exc).split(";")[0]) from None
        if self.port == 0:
            raise OSError(f"cannot bind the LeRobot policy server to {host}:{port}")

    def start(self) -> HoldPositionPolicyServer:
        self.server.start()
        return self

    def stop(self, grace: float = 0.5) -> None:
        self.server.stop(grace).wait()

    # ------------------------------------------------------------------ handlers
    def _ready(self, _request: bytes, _context: Any) -> bytes:
        with self._lock:
            while not self.observations.empty():
                self.observations.get_nowait()
        return b""

    def _setup(self, request: bytes, context: Any) -> bytes:
        try:
            config = wire.loads_wire(wire.decode_fields(request).get(1, b""))
        except Exception as exc:
            context.abort(self._grpc.StatusCode.INVALID_ARGUMENT, f"bad PolicySetup: {exc}")
        if not isinstance(config, wire.RemotePolicyConfig):
            context.abort(self._grpc.StatusCode.INVALID_ARGUMENT, "PolicySetup does not hold a RemotePolicyConfig")
        state = config.lerobot_features.get("observation.state", {})
        if not isinstance(state, dict) or not state.get("names"):
            context.abort(self._grpc.StatusCode.INVALID_ARGUMENT, "lerobot_features lack observation.state names")
        self.config = config
        return b""

    def _observations(self, chunks: Any, context: Any) -> bytes:
        buffer = io.BytesIO()
        for chunk in chunks:
            fields = wire.decode_fields(chunk)
            state = fields.get(1, wire.TRANSFER_UNKNOWN)
            if state == wire.TRANSFER_BEGIN:
                buffer = io.BytesIO()
            buffer.write(fields.get(2, b""))
            if state == wire.TRANSFER_END:
                break
        try:
            observation = wire.loads_wire(buffer.getvalue())
        except Exception as exc:
            context.abort(self._grpc.StatusCode.INVALID_ARGUMENT, f"bad observation: {exc}")
        if not isinstance(observation, wire.TimedObservation):
            context.abort(self._grpc.StatusCode.INVALID_ARGUMENT, "observation is not a TimedObservation")
        with self._lock:  # keep only the freshest observation, as LeRobot's server does
            while not self.observations.empty():
                self.observations.get_nowait()
            self.observations.put_nowait(observation)
            self.received += 1
        return b""

    def _get_actions(self, _request: bytes, context: Any) -> bytes:
        import torch

        if self.config is None:
            context.abort(self._grpc.StatusCode.FAILED_PRECONDITION, "no policy: call SendPolicyInstructions first")
        try:
            observation = self.observations.get(timeout=1.0)
        except queue.Empty:
            return b""  # an empty Actions message: nothing to act on yet
        config = self.config
        assert config is not None  # context.abort above raises, and a set config is never unset
        names = config.lerobot_features["observation.state"]["names"]
        missing = [n for n in names if n not in observation.observation]
        if missing:
            context.abort(self._grpc.StatusCode.INVALID_ARGUMENT, f"observation lacks joints {missing}")
        hold = torch.tensor([float(observation.observation[n]) for n in names], dtype=torch.float32)
        now = time.time()
        actions = [wire.TimedAction(timestamp=now + i / FPS, timestep=observation.timestep + i, action=hold.clone())
                   for i in range(config.actions_per_chunk)]
        return wire.encode_bytes_message(wire.dumps_wire(actions))
