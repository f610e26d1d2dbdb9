"""Encoding messages into one flat frame, and back, without pickle.

Frame layout (all little-endian)::

    u32 meta_len | meta (msgpack) | zero padding to 8 | array bytes, each 8-aligned

``meta`` is the message as nested msgpack lists in field order; every numpy array inside it is
a msgpack extension ``(dtype, shape, offset)`` pointing into the array region. Keeping bulk bytes
outside msgpack means a publisher copies each array exactly once (straight into shared memory)
and a subscriber decodes arrays as zero-copy views of the frame it read.
"""
from __future__ import annotations

import struct
from typing import Any

import attrs
import msgpack
import numpy as np

from emos.msgs import fields as F

_ARRAY_EXT = 1
_U32 = struct.Struct("<I")
_ALIGN = 8


class DecodeError(ValueError):
    """A frame that does not decode into the expected message type."""


def _align(n: int) -> int:
    return (n + _ALIGN - 1) & ~(_ALIGN - 1)


def _layout(cls: type) -> list[tuple[str, str, Any]]:
    """(name, kind, nested class resolver) per field, cached on the class."""
    cached = cls.__dict__.get("_emos_layout")
    if cached is None:
        cached = [(f.name, f.metadata.get("kind", F.PRIMITIVE), f.metadata.get("cls")) for f in attrs.fields(cls)]
        type.__setattr__(cls, "_emos_layout", cached)
    return cached


class Encoded:
    """A message split into its msgpack tree and the arrays it references."""

    __slots__ = ("meta", "arrays", "array_bytes")

    def __init__(self, meta: bytes, arrays: list[np.ndarray], array_bytes: int):
        self.meta = meta
        self.arrays = arrays
        self.array_bytes = array_bytes

    @property
    def header_bytes(self) -> int:
        return _align(_U32.size + len(self.meta))

    @property
    def nbytes(self) -> int:
        return self.header_bytes + self.array_bytes

    def write_into(self, buf: memoryview) -> int:
        """Write the frame into ``buf`` (at least :attr:`nbytes` long); return its length."""
        meta_len = len(self.meta)
        _U32.pack_into(buf, 0, meta_len)
        buf[4 : 4 + meta_len] = self.meta
        pos = self.header_bytes
        for arr in self.arrays:
            n = arr.nbytes
            if n:
                buf[pos : pos + n] = arr.reshape(-1).view(np.uint8)
            pos += _align(n)
        return pos

    def to_bytes(self) -> bytes:
        out = bytearray(self.nbytes)
        self.write_into(memoryview(out))
        return bytes(out)


def encode(msg: Any) -> Encoded:
    """Split ``msg`` (a registered message instance) into an :class:`Encoded` frame."""
    arrays: list[np.ndarray] = []
    offset = 0

    def array_ext(arr: np.ndarray) -> msgpack.ExtType:
        nonlocal offset
        if arr.dtype.hasobject or arr.dtype.fields is not None:
            raise TypeError(f"cannot encode an array of dtype {arr.dtype}: only plain numeric dtypes travel on topics")
        arr = np.ascontiguousarray(arr)
        arrays.append(arr)
        ext = msgpack.ExtType(_ARRAY_EXT, msgpack.packb([arr.dtype.str, list(arr.shape), offset]))
        offset += _align(arr.nbytes)
        return ext

    def tree(obj: Any) -> list:
        out = []
        for name, kind, _ in _layout(type(obj)):
            value = getattr(obj, name)
            if kind == F.ARRAY:
                out.append(array_ext(value))
            elif kind == F.MESSAGE:
                out.append(tree(value))
            elif kind == F.OPTIONAL_MESSAGE:
                out.append(None if value is None else tree(value))
            elif kind == F.MESSAGE_LIST:
                out.append([tree(v) for v in value])
            else:
                out.append(value)
        return out

    meta = msgpack.packb(tree(msg), use_bin_type=True)
    return Encoded(meta, arrays, offset)


def decode(cls: type, frame: Any, copy: bool = False) -> Any:
    """Rebuild a ``cls`` instance from a frame (bytes, bytearray or memoryview).

    Arrays are views into ``frame`` unless ``copy`` is true; pass a buffer you own.
    Field converters are bypassed (the frame came from :func:`encode` of the same layout, which
    the topic's type fingerprint guarantees), so decoding costs little beyond msgpack.
    """
    view = memoryview(frame)
    try:
        (meta_len,) = _U32.unpack_from(view, 0)
        base = _align(_U32.size + meta_len)
        if base > len(view):
            raise DecodeError(f"frame of {len(view)} bytes announces {meta_len} bytes of metadata")

        def ext_hook(code: int, data: bytes) -> Any:
            if code != _ARRAY_EXT:
                raise DecodeError(f"unknown msgpack extension {code}")
            dtype_str, shape, offset = msgpack.unpackb(data)
            dtype = np.dtype(dtype_str)
            count = int(np.prod(shape, dtype=np.int64)) if shape else 1
            start = base + offset
            if start + count * dtype.itemsize > len(view):
                raise DecodeError("array runs past the end of the frame")
            arr = np.frombuffer(view, dtype=dtype, count=count, offset=start).reshape(shape)
            return arr.copy() if copy else arr

        tree = msgpack.unpackb(view[4 : 4 + meta_len], ext_hook=ext_hook, raw=False, strict_map_key=False)
        return _build(cls, tree)
    except DecodeError:
        raise
    except (ValueError, TypeError, IndexError, KeyError, struct.error, msgpack.UnpackException) as exc:
        raise DecodeError(f"cannot decode {cls.__name__}: {exc}") from exc


def _build(cls: type, values: list) -> Any:
    layout = _layout(cls)
    if not isinstance(values, list) or len(values) != len(layout):
        raise DecodeError(f"{cls.__name__} expects {len(layout)} fields, frame has {len(values) if isinstance(values, list) else type(values).__name__}")
    obj = object.__new__(cls)
    for (name, kind, resolver), value in zip(layout, values):
        if kind == F.MESSAGE:
            value = _build(resolver(), value)
        elif kind == F.OPTIONAL_MESSAGE:
            value = None if value is None else _build(resolver(), value)
        elif kind == F.MESSAGE_LIST:
            nested = resolver()
            value = [_build(nested, v) for v in value]
        object.__setattr__(obj, name, value)
    return obj


def pack(msg: Any) -> bytes:
    """One self-contained bytes frame: for sockets and files."""
    return encode(msg).to_bytes()


def unpack(cls: type, data: bytes) -> Any:
    return decode(cls, data, copy=False)


def to_builtin(msg: Any) -> Any:
    """Plain dicts and lists (arrays as lists): for printing, JSON and YAML."""
    if attrs.has(type(msg)):
        return {f.name: to_builtin(getattr(msg, f.name)) for f in attrs.fields(type(msg))}
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    if isinstance(msg, (list, tuple)):
        return [to_builtin(v) for v in msg]
    return msg


def from_builtin(cls: type, data: Any) -> Any:
    """The inverse of :func:`to_builtin`, through the field converters (validated)."""
    if not isinstance(data, dict):
        raise TypeError(f"{cls.__name__} expects a mapping of its fields, got {type(data).__name__}")
    known = {f.name: f for f in attrs.fields(cls)}
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise TypeError(f"{cls.__name__} has no field {', '.join(map(repr, unknown))}; fields are {', '.join(known)}")
    kwargs: dict[str, Any] = {}
    for name, value in data.items():
        meta = known[name].metadata
        kind = meta.get("kind")
        if kind in (F.MESSAGE, F.OPTIONAL_MESSAGE) and isinstance(value, dict):
            value = from_builtin(meta["cls"](), value)
        elif kind == F.MESSAGE_LIST:
            value = [from_builtin(meta["cls"](), v) if isinstance(v, dict) else v for v in value]
        kwargs[name] = value
    return cls(**kwargs)


