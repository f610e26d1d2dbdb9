"""Encoding messages into one flat frame, and back, without pickle.

Frame layout (all little-endian)::

    u32 meta_len | meta (msgpack) | zero padding to 8 | array bytes, each 8-aligned

``meta`` is the message as nested msgpack lists in field order; every numpy array inside it is
a msgpack extension ``(dtype, shape, offset)`` pointing into the array region. Keeping bulk bytes
outside msgpack means a publisher copies each array exactly once (straight into shared memory)
and a subscriber decodes arrays as zero-copy views of the frame it read.
"""
from __future__ import annotations

import math
import os
import re
import struct
import threading
import types
from collections.abc import Mapping
from typing import Any, TypeVar

import attrs
import msgpack
import numpy as np

from emos.errors import EmosError
from emos.msgs import fields as F

_ARRAY_EXT = 1
_U32 = struct.Struct("<I")
_ALIGN = 8
_BULK = 64 * 1024  # arrays at least this big are copied with numpy
_ZEROS = bytes(_ALIGN)
_MEMBER_DESCRIPTOR = types.MemberDescriptorType  # a __slots__ entry


class DecodeError(EmosError, ValueError):
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

    def write_into(self, buf: memoryview, stream: bool = False) -> int:
        """Write the frame into ``buf`` (at least :attr:`nbytes` long); return its length.
        ``stream``: big arrays with streaming stores (see :meth:`write_arrays_into`)."""
        meta_len = len(self.meta)
        _U32.pack_into(buf, 0, meta_len)
        buf[4 : 4 + meta_len] = self.meta
        return self.write_arrays_into(buf, self.header_bytes, stream)

    def write_arrays_into(self, buf: memoryview, start: int = 0, stream: bool = False) -> int:
        """Write the arrays alone, each at its offset from ``start`` (the array region, at least
        :attr:`array_bytes` long from there), into ``buf``; return where the region ends. The
        whole frame (:meth:`write_into`), or a message in two parts, header apart (see
        :meth:`head_chunks`). ``stream``: ``buf`` is shared memory another process reads (a ring
        slot): arrays of :data:`STREAM_MIN_BYTES` or more are then copied with streaming stores,
        which write memory without reading it first; every byte written is visible before this
        returns, so a seqlock commit may follow (``_ccodec.c``)."""
        pos = start
        dst = None
        streaming = _stream_copy if stream else None
        for arr in self.arrays:
            n = arr.nbytes
            if n < _BULK:
                if n:
                    try:
                        # numpy's stubs declare the buffer protocol only for Python >= 3.12:
                        buf[pos : pos + n] = memoryview(arr).cast("B")  # type: ignore[arg-type]  # cheapest for small arrays
                    except TypeError:  # formats memoryview will not cast (e.g. big-endian, float16)
                        buf[pos : pos + n] = arr.reshape(-1).view(np.uint8).tobytes()
            elif streaming is not None and n >= STREAM_MIN_BYTES:
                streaming(buf, pos, arr.reshape(-1).view(np.uint8))
            else:
                if dst is None:
                    dst = np.frombuffer(buf, dtype=np.uint8)
                np.copyto(dst[pos : pos + n], arr.reshape(-1).view(np.uint8))  # cheapest for bulk
            pos += _align(n)
        return pos

    def head_chunks(self) -> list[Any]:
        """The frame's header (metadata length, metadata, padding) as buffers: with
        :meth:`write_arrays_into`, a message in two parts (see :mod:`emos.transport.netframe`,
        large messages over Zenoh), decoded with ``decode(cls, head, arrays=region)``."""
        meta = self.meta
        return [_U32.pack(len(meta)), meta, _ZEROS[: (-_U32.size - len(meta)) % _ALIGN]]

    def chunks(self) -> list[Any]:
        """The frame as consecutive buffers (the header with its metadata and padding, then each
        array and its padding), for ``b"".join``: for a small message one allocation and one
        C call, cheaper than :meth:`write_into` (whose buffer must exist first)."""
        out = self.head_chunks()
        for arr in self.arrays:
            out.append(arr)  # C-contiguous (see _ArrayCollector): joined as its raw bytes
            pad = (-arr.nbytes) % _ALIGN
            if pad:
                out.append(_ZEROS[:pad])
        return out

    def to_bytes(self) -> bytes:
        out = bytearray(self.nbytes)
        self.write_into(memoryview(out))
        return bytes(out)


class _ArrayCollector:
    """Collects the arrays of one message while its msgpack tree is built."""

    __slots__ = ("arrays", "offset")

    def __init__(self) -> None:
        self.arrays: list[np.ndarray] = []
        self.offset = 0

    def __call__(self, arr: np.ndarray) -> msgpack.ExtType:
        if not arr.flags.c_contiguous:
            arr = np.ascontiguousarray(arr)
        dtype, offset = arr.dtype, self.offset
        # Keyed by the dtype's identity, not the dtype: numpy hashes a dtype afresh on every call
        # (0.3-0.6 us, most of this method). The entry keeps its dtype alive and is used only if
        # it holds this very object, so a recycled id can never select another dtype's header.
        entry = _HEADERS_OUT.get((id(dtype), arr.shape, offset))
        if entry is None or entry[0] is not dtype:
            if dtype.hasobject or dtype.fields is not None:
                raise TypeError(f"cannot encode an array of dtype {dtype}: only plain numeric dtypes travel on topics")
            # The ExtType itself is cached: building one checks its fields in Python (~1 us).
            entry = (dtype, msgpack.ExtType(_ARRAY_EXT, msgpack.packb((dtype.str, arr.shape, offset))))
            _remember(_HEADERS_OUT, (id(dtype), arr.shape, offset), entry)
        self.arrays.append(arr)
        self.offset = offset + ((arr.nbytes + _ALIGN - 1) & ~(_ALIGN - 1))  # _align, inlined: once per array
        return entry[1]


# Array headers (dtype, shape, offset) repeat from message to message on a topic (same image
# size, same scan length), so both directions cache them: a dict lookup instead of a msgpack
# round trip, a dtype parse and a product per array.
_HEADERS_OUT: dict[tuple[int, tuple[int, ...], int], tuple[np.dtype, msgpack.ExtType]] = {}  # (id(dtype), shape, offset)
_HEADERS_IN: dict[bytes, tuple[np.dtype, tuple[int, ...], int, int, int]] = {}
_HEADER_CACHE_SIZE = 4096


_K = TypeVar("_K")
_V = TypeVar("_V")


def _remember(cache: dict[_K, _V], key: _K, value: _V) -> None:
    if len(cache) >= _HEADER_CACHE_SIZE:
        cache.clear()  # bounded: topics whose shapes keep changing must not grow memory
    cache[key] = value


_DTYPE_STR = re.compile(r"[<>|=][biufcmMSUV][0-9]{1,6}(\[[0-9]*[A-Za-z]{1,3}\])?")  # e.g. <f8, |u1, <M8[ns], <m8[10s]


def _array_header(data: bytes) -> tuple[np.dtype, tuple[int, ...], int, int, int]:
    """(dtype, shape, count, offset, nbytes) of an encoded array header."""
    spec = _HEADERS_IN.get(data)
    if spec is None:
        dtype_str, shape, offset = msgpack.unpackb(data)
        # Only what the encoder writes (dtype.str of a plain dtype): numpy parses anything else
        # with its own parsers, which answer a forged string with any exception (SyntaxError).
        if type(dtype_str) is not str or not _DTYPE_STR.fullmatch(dtype_str):
            raise DecodeError(f"invalid array dtype {str(dtype_str)[:40]!r}")
        dtype = np.dtype(dtype_str)
        shape = tuple(int(d) for d in shape)
        count = math.prod(shape)
        if dtype.hasobject or offset < 0 or count < 0:
            raise DecodeError(f"invalid array header {dtype_str!r} {shape} at {offset}")
        spec = (dtype, shape, count, int(offset), count * dtype.itemsize)
        _remember(_HEADERS_IN, bytes(data), spec)
    return spec


# Per-class encoders and decoders, generated once as straight-line code (as attrs generates
# __init__): a message is encoded and decoded on every publish and every read, and a generic
# loop over fields costs several times more.
_ENCODERS: dict[type, Any] = {}
_DECODERS: dict[type, Any] = {}


def _encoder(cls: type) -> Any:
    fn = _ENCODERS.get(cls)
    if fn is None:
        fn = _compile_encoder(cls)
    return fn


def _compile_encoder(cls: type) -> Any:
    env: dict[str, Any] = {}
    items = []
    for i, (name, kind, resolver) in enumerate(_layout(cls)):
        if kind == F.ARRAY:
            items.append(f"A(o.{name})")
        elif kind == F.MESSAGE:
            env[f"E{i}"] = _LazyCoder(_encoder, resolver, env, f"E{i}")
            items.append(f"E{i}(o.{name}, A)")
        elif kind == F.OPTIONAL_MESSAGE:
            env[f"E{i}"] = _LazyCoder(_encoder, resolver, env, f"E{i}")
            items.append(f"(None if o.{name} is None else E{i}(o.{name}, A))")
        elif kind == F.MESSAGE_LIST:
            env[f"E{i}"] = _LazyCoder(_encoder, resolver, env, f"E{i}")
            # Mostly empty (a layout's dims, a header-less list): then no comprehension is run.
            items.append(f"([E{i}(x, A) for x in o.{name}] if o.{name} else [])")
        else:
            items.append(f"o.{name}")
    src = f"def encode_{cls.__name__}(o, A):\n    return [{', '.join(items)}]\n"
    exec(compile(src, f"<emos encoder {cls.__name__}>", "exec"), env)  # noqa: S102 - source built above from the layout's field names only
    fn = env[f"encode_{cls.__name__}"]
    _ENCODERS[cls] = fn
    return fn


def _decoder(cls: type) -> Any:
    fn = _DECODERS.get(cls)
    if fn is None:
        fn = _compile_decoder(cls)
    return fn


def _compile_decoder(cls: type) -> Any:
    layout = _layout(cls)
    env: dict[str, Any] = {"new": object.__new__, "sa": object.__setattr__, "cls": cls, "DecodeError": DecodeError, "n": len(layout)}
    lines = [
        f"def decode_{cls.__name__}(v):",
        "    if type(v) is not list or len(v) != n:",
        f"        raise DecodeError(f'{cls.__name__} expects {{n}} fields, frame has {{len(v) if type(v) is list else type(v).__name__}}')",
        "    o = new(cls)",
    ]
    for i, (name, kind, resolver) in enumerate(layout):
        # A slot's own setter: half the cost of object.__setattr__ (which looks the name up), and
        # like it, it bypasses the class's __setattr__ and so the field converters.
        slot = cls.__dict__.get(name)
        if type(slot) is _MEMBER_DESCRIPTOR:
            env[f"S{i}"] = slot.__set__
            setter = f"S{i}(o, "
        else:
            setter = f"sa(o, '{name}', "
        if kind == F.MESSAGE:
            env[f"D{i}"] = _LazyCoder(_decoder, resolver, env, f"D{i}")
            lines.append(f"    {setter}D{i}(v[{i}]))")
        elif kind == F.OPTIONAL_MESSAGE:
            env[f"D{i}"] = _LazyCoder(_decoder, resolver, env, f"D{i}")
            lines.append(f"    {setter}None if v[{i}] is None else D{i}(v[{i}]))")
        elif kind == F.MESSAGE_LIST:
            env[f"D{i}"] = _LazyCoder(_decoder, resolver, env, f"D{i}")
            lines.append(f"    {setter}[D{i}(x) for x in v[{i}]])")
        else:
            lines.append(f"    {setter}v[{i}])")
    lines.append("    return o")
    exec(compile("\n".join(lines) + "\n", f"<emos decoder {cls.__name__}>", "exec"), env)  # noqa: S102 - field names only, as above
    fn = env[f"decode_{cls.__name__}"]
    _DECODERS[cls] = fn
    return fn


class _LazyCoder:
    """Resolves a nested message class on first use (classes may refer to later ones), then
    puts the resolved coder in its place in the generated code's globals, so later calls go
    straight to it instead of through this object."""

    __slots__ = ("factory", "resolver", "fn", "env", "name")

    def __init__(self, factory: Any, resolver: Any, env: dict[str, Any], name: str):
        self.factory, self.resolver, self.fn = factory, resolver, None
        self.env, self.name = env, name

    def __call__(self, *args: Any) -> Any:
        fn = self.fn
        if fn is None:
            fn = self.fn = self.factory(self.resolver())
            self.env[self.name] = fn
        return fn(*args)


# One msgpack Packer per thread, reused: ``msgpack.packb`` builds a new Packer on every call,
# which is most of the cost of packing a small message (about 1.3 us of 2 here). A Packer is not
# thread-safe (it keeps its buffer between calls), hence one per thread; it empties its buffer
# after every pack, also when packing raises.
_packers = threading.local()


def _packer() -> msgpack.Packer:
    try:
        packer: msgpack.Packer = _packers.packer
        return packer
    except AttributeError:
        packer = _packers.packer = msgpack.Packer(use_bin_type=True)
        return packer


def encode_python(msg: Any) -> Encoded:
    """Split ``msg`` (a registered message instance) into an :class:`Encoded` frame: the Python
    codec (:func:`encode` is the C fast path when built, which falls back to this)."""
    arrays = _ArrayCollector()
    cls = type(msg)
    tree = (_ENCODERS.get(cls) or _compile_encoder(cls))(msg, arrays)
    try:
        packer = _packers.packer
    except AttributeError:
        packer = _packer()
    return Encoded(packer.pack(tree), arrays.arrays, arrays.offset)


def decode_python(cls: type, frame: Any, copy: bool = False, arrays: Any = None) -> Any:
    """Rebuild a ``cls`` instance from a frame (bytes, bytearray or memoryview): the Python codec
    (:func:`decode` is the C fast path when built, which falls back to this).

    Arrays are views into ``frame`` unless ``copy`` is true; pass a buffer you own.
    ``arrays``: the array region when it travels apart from the header (see
    :meth:`Encoded.head_chunks`); ``frame`` is then the header alone, and arrays are views of
    ``arrays``. Field converters are bypassed (the frame came from :func:`encode` of the same
    layout, which the topic's type fingerprint guarantees), so decoding costs little beyond msgpack.
    """
    view = memoryview(frame)
    try:
        (meta_len,) = _U32.unpack_from(view, 0)
        base = (_U32.size + meta_len + _ALIGN - 1) & ~(_ALIGN - 1)  # _align, inlined: once per message
        end = len(view)
        if base > end:
            raise DecodeError(f"frame of {end} B announces {meta_len} bytes of metadata")
        meta = view[4 : 4 + meta_len]
        if arrays is not None:
            view = memoryview(arrays)
            base, end = 0, len(view)

        def ext_hook(code: int, data: bytes) -> Any:
            if code != _ARRAY_EXT:
                raise DecodeError(f"unknown msgpack extension {code}")
            dtype, shape, count, offset, nbytes = _array_header(data)
            start = base + offset
            if start + nbytes > end:
                raise DecodeError("array runs past the end of the frame")
            # The array constructor with positional arguments: half the cost of frombuffer's
            # keywords plus a reshape, for the same read-only view (bounds checked above).
            arr = np.ndarray(shape, dtype, view, start)
            return arr.copy() if copy else arr

        tree = msgpack.unpackb(meta, ext_hook=ext_hook, raw=False, strict_map_key=False)
        return (_DECODERS.get(cls) or _compile_decoder(cls))(tree)
    except DecodeError:
        raise
    except (ValueError, TypeError, IndexError, KeyError, struct.error, msgpack.UnpackException) as exc:
        raise DecodeError(f"cannot decode {cls.__name__}: {exc}") from exc


# ------------------------------------------------------------------------ the C fast path
# emos/msgs/_ccodec.c writes and reads the same frames in one C call per message. It returns
# exactly what the functions above return, or gives up and they run instead (any value or byte
# it does not handle, every error): see that file for why, and tests/runtime/test_ccodec.py.
_C_KINDS = {F.ARRAY: 1, F.MESSAGE: 2, F.OPTIONAL_MESSAGE: 3, F.MESSAGE_LIST: 4}  # anything else is a plain value


def _c_plan(cls: type) -> tuple[tuple[int, Any, type | None], ...] | None:
    """What the C codec needs of ``cls``: per field, in order, (kind, the slot's member
    descriptor or the field's name, the nested message class or None); None if the C codec
    must leave ``cls`` to the Python one. The generated coders above read and set fields the
    same way."""
    if not attrs.has(cls) or cls.__new__ is not object.__new__:
        return None
    plan: list[tuple[int, Any, type | None]] = []
    for name, kind, resolver in _layout(cls):
        slot = cls.__dict__.get(name)
        code = _C_KINDS.get(kind, 0)
        plan.append((code, slot if type(slot) is _MEMBER_DESCRIPTOR else name, resolver() if code >= 2 else None))
    return tuple(plan)


def _load_c_codec() -> Any:
    """The C fast path's module, set up, if it was built and not turned off with
    ``EMOS_CODEC=python``; else None."""
    if os.environ.get("EMOS_CODEC", "").lower() == "python":
        return None
    try:
        from emos.msgs import _ccodec
    except ImportError:  # installed without a C compiler: the Python codec alone, same frames
        return None
    slots = tuple(Encoded.__dict__[name] for name in Encoded.__slots__)  # the slots' member descriptors
    _ccodec.setup(Encoded, slots, _HEADERS_IN, _array_header, _c_plan, encode_python, decode_python)
    return _ccodec


C_CODEC = _load_c_codec()  # the C module in use (emos.transport.netframe uses its frame functions too), or None
encode, decode = (C_CODEC.encode, C_CODEC.decode) if C_CODEC is not None else (encode_python, decode_python)

# Writing into a ring slot (``write_into(..., stream=True)``, what a publisher does), arrays of
# at least STREAM_MIN_BYTES are copied with non-temporal (streaming) stores: they write memory
# without first taking every line of it into this core's cache, which a plain copy does, from
# memory or from the cache of the reader's core that read the slot last (_ccodec.c, "streaming
# copy", also says how the ring's seqlock stays intact). Which is faster depends on whether the
# slots a topic cycles through stay in the last-level cache (docs/ipc.md, "Streaming copies" and
# "Plain or streaming: the last-level cache decides"): a ping-pong of two rings cycles about four
# slots of the message's size. When those fit in half the last-level cache, a plain copy writes
# into the cache the reader takes its lines from, and streaming would push every line out to
# memory and make the reader fetch it back (measured on a VM with a 260 MiB L3: 921,600 B 75-81
# us plain against 120-141 streaming, 8 MiB 676-697 against 1,141-1,377); when they do not, every
# line comes from memory anyway and a plain copy's read-for-ownership doubles the traffic (a VM
# with a 32 MiB L3: 8 MiB 410-420 us streaming against 615-770 plain). So streaming starts at an
# eighth of the last-level cache (at least 128 KiB, below which a copy takes a few microseconds
# either way; 128 KiB when the cache size is unknown). ``EMOS_STREAM_MIN_BYTES`` sets it.
# The Python codec (no compiler, or EMOS_CODEC=python) copies with numpy: the same bytes.
_STREAM_FLOOR = 128 * 1024


def last_level_cache_bytes(cache_dir: str = "/sys/devices/system/cpu/cpu0/cache") -> int | None:
    """The size of the largest data or unified cache of CPU 0 (the last level), from sysfs; None
    when it cannot be read (not Linux, a container without sysfs, a malformed entry)."""
    sizes = []
    try:
        for entry in sorted(os.listdir(cache_dir)):
            if not entry.startswith("index"):
                continue
            with open(os.path.join(cache_dir, entry, "type")) as f:
                if f.read().strip() == "Instruction":
                    continue
            with open(os.path.join(cache_dir, entry, "size")) as f:
                text = f.read().strip()
            scale = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}.get(text[-1:].upper(), 1)
            sizes.append(int(text[:-1] if scale != 1 else text) * scale)
    except (OSError, ValueError):
        return None
    return max(sizes) if sizes else None


def stream_min_bytes(environ: Mapping[str, str] = os.environ, cache_bytes: int | None = None) -> int:
    """The size from which a publisher streams an array into its ring slot: ``EMOS_STREAM_MIN_BYTES``
    if set (bytes, a whole number >= 0), else an eighth of the last-level cache
    (``cache_bytes``, default :func:`last_level_cache_bytes`), at least 128 KiB."""
    text = environ.get("EMOS_STREAM_MIN_BYTES", "").strip()
    if text:
        try:
            value = int(text)
        except ValueError:
            value = -1
        if value < 0:
            raise ValueError(f"EMOS_STREAM_MIN_BYTES: expected a whole number of bytes >= 0, got {text!r}")
        return value
    cache = last_level_cache_bytes() if cache_bytes is None else cache_bytes
    return _STREAM_FLOOR if not cache else max(_STREAM_FLOOR, cache // 8)


STREAM_MIN_BYTES = stream_min_bytes()
_stream_copy: Any = getattr(C_CODEC, "stream_copy", None)


def check_header(frame: Any, offset: int = 0) -> None:
    """Raise :class:`DecodeError` unless the frame at ``offset`` of ``frame`` has room for the
    metadata length it announces: the check a receiver can afford before it decodes."""
    end = len(frame)
    if offset + _U32.size > end:
        raise DecodeError(f"a message frame of {end - offset} B has no room for its header")
    (meta_len,) = _U32.unpack_from(frame, offset)
    if offset + ((_U32.size + meta_len + _ALIGN - 1) & ~(_ALIGN - 1)) > end:  # _align, inlined: once per network message
        raise DecodeError(f"a message frame of {end - offset} B announces {meta_len} bytes of metadata")


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


