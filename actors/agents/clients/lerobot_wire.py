"""LeRobot async-inference wire format: protobuf messages (hand-encoded) and pickled payloads.

LeRobot's ``transport/services.proto`` (service ``transport.AsyncInference``) carries opaque
``bytes``: the policy setup, observations and actions are *pickled* instances of dataclasses
from ``lerobot.async_inference.helpers`` (``RemotePolicyConfig``, ``TimedObservation``,
``TimedAction`` whose ``action`` is a torch tensor). To talk to a real policy server without
installing lerobot we:

- encode the five tiny protobuf messages by hand (no generated code, no grpcio-tools);
- pickle local mirror dataclasses under lerobot's module path, so the server unpickles them
  as its own classes;
- unpickle replies with an allow-list unpickler (only those classes, tensor rebuilding with
  ``torch.load(weights_only=True)``, numpy arrays), because unpickling arbitrary bytes from
  the network would let any server run code on the robot.
"""
from __future__ import annotations

import io
import os
import pickle
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "HELPERS_MODULE", "SERVICE", "TRANSFER_BEGIN", "TRANSFER_MIDDLE", "TRANSFER_END",
    "RemotePolicyConfig", "TimedObservation", "TimedAction",
    "encode_bytes_message", "encode_chunk", "decode_fields", "chunk_payload",
    "dumps_wire", "loads_wire", "import_grpc",
]

HELPERS_MODULE = "lerobot.async_inference.helpers"
SERVICE = "transport.AsyncInference"
TRANSFER_UNKNOWN, TRANSFER_BEGIN, TRANSFER_MIDDLE, TRANSFER_END = 0, 1, 2, 3
#: gRPC's default message limit is 4 MB; LeRobot chunks observations well below it.
CHUNK_BYTES = 3 * 1024 * 1024


# ------------------------------------------------------------------ protobuf wire format


def _varint(value: int) -> bytes:
    out = bytearray()
    value &= (1 << 64) - 1
    while True:
        byte = value & 0x7F
        value >>= 7
        if value:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def encode_bytes_message(data: bytes, field_number: int = 1) -> bytes:
    """A message whose only field is ``bytes data = field_number`` (Actions, PolicySetup)."""
    return _varint(field_number << 3 | 2) + _varint(len(data)) + data if data else b""


def encode_chunk(state: int, data: bytes) -> bytes:
    """``Observation {TransferState transfer_state = 1; bytes data = 2;}``."""
    out = _varint(1 << 3 | 0) + _varint(state) if state else b""
    return out + encode_bytes_message(data, 2)


def decode_fields(buf: bytes) -> dict[int, Any]:
    """Decode a flat protobuf message into {field number: last value} (bytes, int or raw fixed)."""
    fields: dict[int, Any] = {}
    i, n = 0, len(buf)

    def varint() -> int:
        nonlocal i
        shift = result = 0
        while True:
            if i >= n:
                raise ValueError("truncated protobuf varint")
            byte = buf[i]
            i += 1
            result |= (byte & 0x7F) << shift
            if not byte & 0x80:
                return result
            shift += 7
            if shift > 63:
                raise ValueError("protobuf varint too long")

    while i < n:
        key = varint()
        number, wire = key >> 3, key & 7
        if wire == 0:
            fields[number] = varint()
        elif wire == 2:
            size = varint()
            if i + size > n:
                raise ValueError("truncated protobuf length-delimited field")
            fields[number] = buf[i : i + size]
            i += size
        elif wire == 1:
            fields[number] = buf[i : i + 8]
            i += 8
        elif wire == 5:
            fields[number] = buf[i : i + 4]
            i += 4
        else:
            raise ValueError(f"unsupported protobuf wire type {wire}")
    return fields


def chunk_payload(data: bytes, size: int = CHUNK_BYTES) -> Iterator[bytes]:
    """Split a pickled payload into encoded Observation messages (BEGIN, MIDDLE..., END)."""
    total = len(data)
    offsets = list(range(0, max(total, 1), size))
    for k, start in enumerate(offsets):
        last = k == len(offsets) - 1
        state = TRANSFER_END if last else (TRANSFER_BEGIN if k == 0 else TRANSFER_MIDDLE)
        yield encode_chunk(state, data[start : start + size])


# ------------------------------------------------------------------ pickled payloads


@dataclass
class RemotePolicyConfig:
    policy_type: str
    pretrained_name_or_path: str
    lerobot_features: dict
    actions_per_chunk: int
    device: str = "cpu"
    rename_map: dict = field(default_factory=dict)


@dataclass
class TimedData:
    timestamp: float
    timestep: int


@dataclass
class TimedObservation(TimedData):
    observation: dict
    must_go: bool = False


@dataclass
class TimedAction(TimedData):
    action: Any


_WIRE_CLASSES = {cls: cls.__name__ for cls in (RemotePolicyConfig, TimedData, TimedObservation, TimedAction)}


# The pure-Python pickler lets us name globals ourselves. typeshed declares only its public
# surface (no save, save_global, write, memoize, which the subclass below uses): typed as Any.
_PurePythonPickler: Any = pickle._Pickler


class _WirePickler(_PurePythonPickler):
    def save_global(self, obj: Any, name: str | None = None) -> None:
        wire_name = _WIRE_CLASSES.get(obj)
        if wire_name is None:
            return super().save_global(obj, name)
        self.save(HELPERS_MODULE)
        self.save(wire_name)
        self.write(pickle.STACK_GLOBAL)
        self.memoize(obj)


def dumps_wire(obj: Any) -> bytes:
    """Pickle with the mirror classes named as lerobot's own (protocol 4)."""
    buf = io.BytesIO()
    _WirePickler(buf, protocol=4).dump(obj)
    return buf.getvalue()


def _safe_load_tensor_bytes(data: bytes) -> Any:
    import torch

    return torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)


class _AllowListUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> Any:
        if module == HELPERS_MODULE:
            for cls, wire_name in _WIRE_CLASSES.items():
                if wire_name == name:
                    return cls
        if (module, name) == ("collections", "OrderedDict"):
            import collections

            return collections.OrderedDict
        if module in ("numpy.core.multiarray", "numpy._core.multiarray") and name in ("_reconstruct", "scalar"):
            import importlib

            import numpy as np

            multiarray = importlib.import_module("numpy._core.multiarray" if hasattr(np, "_core") else "numpy.core.multiarray")
            return getattr(multiarray, name)
        if (module, name) in (("numpy", "ndarray"), ("numpy", "dtype")):
            import numpy as np

            return getattr(np, name)
        if module == "numpy.dtypes" and name.endswith("DType"):
            import numpy.dtypes

            return getattr(numpy.dtypes, name)
        if (module, name) == ("torch._utils", "_rebuild_tensor_v2"):
            try:
                import torch._utils
            except ImportError:
                raise pickle.UnpicklingError("decoding LeRobot actions needs torch: pip install 'emos[agents]'") from None
            return torch._utils._rebuild_tensor_v2
        if (module, name) == ("torch.storage", "_load_from_bytes"):
            return _safe_load_tensor_bytes
        raise pickle.UnpicklingError(f"refusing to unpickle {module}.{name} from a policy server")


def loads_wire(data: bytes) -> Any:
    """Unpickle a LeRobot payload, allowing only the wire classes, tensors and numpy arrays."""
    return _AllowListUnpickler(io.BytesIO(data)).load()


def import_grpc() -> Any:
    """grpc, imported with its fork support off (both our LeRobot client and server use this).

    The processes that hold a gRPC channel or server only ever fork to exec (subprocess), which
    needs no fork support; with it on, a fork races gRPC's poller thread (grpc/grpc#43055: the
    child's restarted poller meets a closed epoll descriptor, "epoll_wait error: Bad file
    descriptor"), which ended the model server at start-up now and then on a busy machine.
    An explicit setting in the environment wins."""
    os.environ.setdefault("GRPC_ENABLE_FORK_SUPPORT", "false")
    try:
        import grpc
    except ImportError:
        raise ImportError("LeRobot needs grpcio: pip install grpcio (and torch, from 'emos[agents]')") from None
    return grpc
