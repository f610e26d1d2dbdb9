"""Our message classes as ROS 2 CDR bytes, and back.

A message type is *shared* with ROS 2 when its canonical name (``sensor_msgs/msg/LaserScan``)
is a type of the chosen ROS 2 distribution and both sides declare the same fields with
compatible kinds (a nested message where ROS has one, a numeric array where ROS has a numeric
array or sequence, ...). For shared types :class:`Ros2Codec` converts an attrs message to the
ROS 2 side's message object of `rosbags <https://gitlab.com/ternaris/rosbags>`_ and lets
rosbags' CDR serializer write the bytes (XCDR1 with the 4-byte encapsulation header, little
endian), so the ROS 2 type definitions and the wire format come from a maintained library and
not from us. Types that are not shared (our own packages, or a field ROS lacks) are refused
with an error naming the difference; callers fall back to our msgpack frames for them.

The codec does not know how bytes travel (MCAP files, the Foxglove bridge, later Zenoh).
"""
from __future__ import annotations

import logging
import struct
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import attrs
import numpy as np

from emos.errors import EmosError
from emos.msgs import fields as F
from emos.msgs.registry import canonical_name, registered_types

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

log = logging.getLogger("emos.interop")

# ROS 2 distributions whose type definitions rosbags ships (its typestores).
DISTRIBUTIONS = ("humble", "iron", "jazzy", "kilted")
DEFAULT_DISTRIBUTION = "humble"

# rosbags Nodetype values (rosbags.interfaces.Nodetype): BASE, NAME, ARRAY, SEQUENCE.
_BASE, _NAME, _ARRAY, _SEQUENCE = 1, 2, 3, 4
_NUMERIC = {
    "bool": "bool", "byte": "uint8", "char": "uint8", "octet": "uint8",
    "int8": "int8", "uint8": "uint8", "int16": "int16", "uint16": "uint16",
    "int32": "int32", "uint32": "uint32", "int64": "int64", "uint64": "uint64",
    "float32": "float32", "float64": "float64",
}
# ROS 2 gives field-less messages one placeholder byte (rosidl's rule for empty structures).
_PLACEHOLDER = "structure_needs_at_least_one_member"
# A message whose last field is a numeric sequence at least this large (an Image's or a
# UInt8MultiArray's data, an OccupancyGrid's cells) is written with one copy of that array
# (:meth:`Ros2Codec.serialize`); smaller ones go through rosbags alone.
SPLICE_MIN_BYTES = 64 * 1024


class NotShared(EmosError, LookupError):
    """A message type with no ROS 2 counterpart of the same layout."""


class CdrError(EmosError, ValueError):
    """Bytes that are not a valid CDR encoding of the expected ROS 2 type, or a value CDR cannot hold."""


def _typestore(distribution: str) -> Typestore:
    try:
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError("ROS 2 interop needs rosbags: pip install 'emos[ecosystem]'") from exc
    if distribution not in DISTRIBUTIONS:
        raise ValueError(f"unknown ROS 2 distribution {distribution!r}; rosbags provides {', '.join(DISTRIBUTIONS)}")
    return get_typestore(getattr(Stores, f"ROS2_{distribution.upper()}"))


class Ros2Codec:
    """Converts shared message types to and from ROS 2 CDR, following one ROS 2 distribution."""

    def __init__(self, distribution: str = DEFAULT_DISTRIBUTION):
        self.distribution = distribution
        self.store = _typestore(distribution)
        self._to: dict[type, Callable[[Any], Any]] = {}
        self._from: dict[type, Callable[[Any], Any]] = {}
        self._why_not: dict[type, str] = {}
        self._msgdefs: dict[type, str] = {}
        # Per class whose last field is a numeric sequence: (field, its converter, the other
        # fields' converters, the rosbags class, the element size).
        self._tail: dict[type, tuple[str, Callable[[Any], Any], list[tuple[str, Callable[[Any], Any]]], Any, int]] = {}
        self.spliced_bytes = 0  # array bytes written by serialize()'s one-copy path (tests count them)
        # Per shared class: (ROS 2 type name, to_ros, from_ros), looked up once per message by
        # serialize()/deserialize() (the bridge calls them for every sample it moves).
        self._entries: dict[type, tuple[str, Callable[[Any], Any], Callable[[Any], Any]]] = {}

    # -- which types ---------------------------------------------------------------------------
    def ros_type(self, cls: type) -> str:
        """The ROS 2 type name of a shared class (``sensor_msgs/msg/Image``); raises :class:`NotShared`."""
        self._plan(cls)
        return canonical_name(cls)

    def is_shared(self, cls: type) -> bool:
        try:
            self._plan(cls)
            return True
        except NotShared:
            return False

    def shared_types(self) -> dict[str, type]:
        """Every registered class that is shared, by ROS 2 type name."""
        return {name: cls for name, cls in sorted(registered_types().items()) if self.is_shared(cls)}

    def class_for(self, ros_type: str) -> type:
        """Our class for a ROS 2 type name, if that type is shared."""
        cls = registered_types().get(ros_type)
        if cls is None:
            raise NotShared(f"ROS 2 type {ros_type!r} has no EMOS message class")
        self._plan(cls)
        return cls

    def message_definition(self, cls: type) -> str:
        """The full ``ros2msg`` definition (the type's fields, then every nested type), as rosbag2 writes it into MCAP."""
        text = self._msgdefs.get(cls)
        if text is None:
            text = self.store.generate_msgdef(self.ros_type(cls), ros_version=2)[0]
            self._msgdefs[cls] = text
        return text

    # -- conversion ----------------------------------------------------------------------------
    def _entry(self, cls: type) -> tuple[str, Callable[[Any], Any], Callable[[Any], Any]]:
        """``(ROS 2 type name, to_ros, from_ros)`` of a shared class; raises :class:`NotShared`."""
        entry = self._entries.get(cls)
        if entry is None:
            to, frm = self._plan(cls)
            entry = self._entries[cls] = (canonical_name(cls), to, frm)
        return entry

    def to_ros(self, msg: Any) -> Any:
        """The rosbags message object equal to ``msg``."""
        return self._plan(type(msg))[0](msg)

    def from_ros(self, cls: type, obj: Any) -> Any:
        return self._plan(cls)[1](obj)

    def serialize(self, msg: Any) -> bytes:
        """``msg`` as ROS 2 CDR bytes (encapsulation header included).

        rosbags writes into a zero-filled buffer that ``bytes`` then copies again (rclpy's raw
        publish takes only ``bytes``): for a 921,600 B image that is a fill and two copies of
        the pixels. When the message ends in a large numeric sequence, the fields before it are
        written by rosbags with that sequence empty, and the sequence's length and elements are
        appended in one ``join``: one copy of the array (``spliced_bytes`` counts them). The
        sequence is the last field, so no later field's alignment depends on where it ends."""
        cls = type(msg)
        if cls not in self._entries:
            self._entry(cls)  # NotShared for a class ROS 2 lacks, as serialize_view would say
        tail = self._tail.get(cls) if sys.byteorder == "little" else None  # the bytes appended are native-order
        if tail is not None:
            fname, to_array, head_steps, ros_cls, itemsize = tail
            arr = to_array(getattr(msg, fname))
            if arr.nbytes >= SPLICE_MIN_BYTES:
                name = self._entries[cls][0]
                try:
                    fields = {f: conv(getattr(msg, f)) for f, conv in head_steps}
                    head = self.store.serialize_cdr(ros_cls(**fields, **{fname: arr[:0]}), name)
                except Exception as exc:  # as serialize_view's
                    raise CdrError(f"cannot encode {name} as CDR: {exc}") from exc
                # head ends with the empty sequence's uint32 length; CDR aligns 8-byte elements
                # to 8 from the start of the body (after the 4-byte encapsulation header).
                pad = b"\0\0\0\0" if itemsize == 8 and (len(head) - 4) % 8 else b""
                self.spliced_bytes += arr.nbytes
                return b"".join((head[:-4], struct.pack("<I", arr.size), pad, arr))
        return bytes(self.serialize_view(msg))

    def serialize_view(self, msg: Any) -> memoryview:
        """As :meth:`serialize`, without the final copy: a view of a fresh buffer (for writers)."""
        name, to_ros, _ = self._entries.get(type(msg)) or self._entry(type(msg))
        ros_msg = to_ros(msg)
        try:
            return self.store.serialize_cdr(ros_msg, name)
        except Exception as exc:  # struct.error (a value out of range), rosbags' own errors, ...
            raise CdrError(f"cannot encode {name} as CDR: {exc}") from exc

    def deserialize(self, cls: type, data: bytes | memoryview) -> Any:
        """A ``cls`` instance from ROS 2 CDR bytes; :class:`CdrError` for bytes that do not decode."""
        name, _, from_ros = self._entries.get(cls) or self._entry(cls)
        raw = data if type(data) is bytes else bytes(data)  # (bytes(bytes) is no copy either, but a call)
        if len(raw) < 4 or raw[0] != 0 or raw[1] not in (0, 1):
            raise CdrError(f"{name}: not a CDR payload (encapsulation header {raw[:4].hex() or 'missing'}, expected 0000 or 0001 ....)")
        try:
            # A memoryview: rosbags slices off the 4-byte header, which for bytes copies the
            # whole payload (a 921,600 B image once more per message).
            obj = self.store.deserialize_cdr(memoryview(raw), name)
        except Exception as exc:  # rosbags raises struct.error, IndexError, UnicodeDecodeError, ...
            raise CdrError(f"cannot decode {len(raw)} bytes as {name}: {exc}") from exc
        return from_ros(obj)

    # -- plans: one pair of converters per class, built on first use --------------------------
    def _plan(self, cls: type) -> tuple[Callable[[Any], Any], Callable[[Any], Any]]:
        to = self._to.get(cls)
        if to is not None:
            return to, self._from[cls]
        if cls in self._why_not:
            raise NotShared(self._why_not[cls])
        try:
            to, frm = self._build(cls)
        except NotShared as exc:
            self._why_not[cls] = str(exc)
            raise
        self._to[cls], self._from[cls] = to, frm
        return to, frm

    def _build(self, cls: type) -> tuple[Callable[[Any], Any], Callable[[Any], Any]]:
        name = canonical_name(cls)
        if name not in self.store.fielddefs:
            raise NotShared(f"{name} is not a ROS 2 {self.distribution} type")
        ros_fields = dict(self.store.fielddefs[name][1])
        ros_cls = self.store.types[name]
        ours = [(f.name, f.metadata.get("kind", F.PRIMITIVE), f.metadata.get("cls")) for f in attrs.fields(cls)]
        ros_only = sorted(set(ros_fields) - {n for n, _, _ in ours} - {_PLACEHOLDER})
        emos_only = sorted({n for n, _, _ in ours} - set(ros_fields))
        if ros_only or emos_only:
            raise NotShared(f"{name}: fields differ from ROS 2 {self.distribution} "
                            f"(only in ROS: {ros_only or 'none'}; only in EMOS: {emos_only or 'none'})")
        to_steps: list[tuple[str, Callable[[Any], Any]]] = []
        from_steps: list[tuple[str, Callable[[Any], Any]]] = []
        for fname, kind, resolver in ours:
            to_conv, from_conv = self._field(name, fname, kind, resolver, ros_fields[fname])
            to_steps.append((fname, to_conv))
            from_steps.append((fname, from_conv))

        last_name, last_kind, _ = ours[-1] if ours else ("", "", None)
        if last_kind == F.ARRAY and ros_fields[last_name][0] == _SEQUENCE:
            itemsize = np.dtype(_NUMERIC[ros_fields[last_name][1][0][1][0]]).itemsize
            self._tail[cls] = (last_name, to_steps[-1][1], to_steps[:-1], ros_cls, itemsize)

        def to_ros(msg: Any) -> Any:
            return ros_cls(**{f: conv(getattr(msg, f)) for f, conv in to_steps})

        def from_ros(obj: Any) -> Any:
            return cls(**{f: conv(getattr(obj, f)) for f, conv in from_steps})

        return to_ros, from_ros

    def _field(self, owner: str, fname: str, kind: str, resolver: Any, ros: tuple[Any, Any]) -> tuple[Callable[[Any], Any], Callable[[Any], Any]]:
        node, spec = ros
        where = f"{owner}.{fname}"
        if kind == F.MESSAGE:
            if node != _NAME:
                raise NotShared(f"{where}: EMOS nests a message, ROS 2 has {spec}")
            nested = resolver()
            if canonical_name(nested) != spec:
                raise NotShared(f"{where}: EMOS nests {canonical_name(nested)}, ROS 2 {spec}")
            to, frm = self._plan(nested)
            return to, frm
        if kind == F.MESSAGE_LIST:
            if node != _SEQUENCE or spec[0][0] != _NAME:
                raise NotShared(f"{where}: EMOS has a list of messages, ROS 2 {spec}")
            nested = resolver()
            if canonical_name(nested) != spec[0][1]:
                raise NotShared(f"{where}: EMOS lists {canonical_name(nested)}, ROS 2 {spec[0][1]}")
            to, frm = self._plan(nested)
            return (lambda v: [to(x) for x in v]), (lambda v: [frm(x) for x in v])
        if kind == F.STR_LIST:
            if node != _SEQUENCE or spec[0] != (_BASE, ("string", 0)):
                raise NotShared(f"{where}: EMOS has a list of strings, ROS 2 {spec}")
            return list, list
        if kind == F.ARRAY:
            if node not in (_ARRAY, _SEQUENCE) or spec[0][0] != _BASE or spec[0][1][0] not in _NUMERIC:
                raise NotShared(f"{where}: EMOS has a numeric array, ROS 2 {spec}")
            dtype = np.dtype(_NUMERIC[spec[0][1][0]])
            length = spec[1] if node == _ARRAY else 0

            def to_array(v: Any) -> np.ndarray:
                arr = np.ascontiguousarray(v, dtype=dtype).reshape(-1)
                if length and arr.size != length:
                    raise CdrError(f"{where} must hold {length} values for ROS 2, has {arr.size}")
                return arr

            return to_array, np.asarray
        if kind == F.PRIMITIVE:
            if node != _BASE:
                raise NotShared(f"{where}: EMOS has a plain value, ROS 2 {spec}")
            base = spec[0]
            if base == "string":
                return str, str
            if base == "bool":
                return bool, bool
            if base in ("float32", "float64"):
                return float, float
            if base in _NUMERIC:
                return int, int
            raise NotShared(f"{where}: ROS 2 type {base} has no EMOS counterpart")
        raise NotShared(f"{where}: EMOS field kind {kind!r} has no ROS 2 counterpart")


_DEFAULT: dict[str, Ros2Codec] = {}


def codec_for(distribution: str = DEFAULT_DISTRIBUTION) -> Ros2Codec:
    """One shared codec per distribution (typestores and conversion plans are built once)."""
    codec = _DEFAULT.get(distribution)
    if codec is None:
        codec = _DEFAULT[distribution] = Ros2Codec(distribution)
    return codec
