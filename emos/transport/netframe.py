"""The frame of one EMOS message on a network transport (Zenoh), and its defensive reader.

A frame is a small fixed header, the message type's fingerprint, the publisher's name, then the
message itself in EMOS's own encoding (msgpack metadata + raw, aligned arrays; see
:mod:`emos.msgs.codec`), byte for byte what a shared-memory ring holds::

    "EMZ1" | stamp_ns u64 | fingerprint length u16 | publisher length u16 | fingerprint | publisher | padding to 8 | payload

The payload starts 8-byte aligned within the frame, so the arrays in it can be viewed in place.

A large message (arrays of :attr:`FrameWriter.SPLIT` bytes or more) travels in two parts
instead: the sample's attachment holds the same header with magic ``"EMZ2"`` and the message's
metadata alone, and the sample's payload holds its array region. That spares a copy wherever
the array already lives in a ``bytes`` object, as every array a subscriber decoded does: a
component that forwards a camera image hands Zenoh the very bytes it received (zenoh-python
takes only ``bytes``/``bytearray``, so any other array must be copied once to reach it).
Anything can arrive on a key expression (another program, another version, a forged sender), so
:func:`read_frame` checks every length against the frame before it slices; the subscriber then
decodes the body, and drops it if it does not decode (see
:class:`emos.transport.zenoh_net.ZenohSubscriber`).
"""
from __future__ import annotations

import struct
from typing import Any

from emos.errors import TransportError
from emos.msgs import codec

MAGIC = b"EMZ1"
SPLIT_MAGIC = b"EMZ2"  # the attachment of a message whose arrays are the sample's payload
_HEADER = struct.Struct("<4sQHH")
_MAGIC_STAMP = struct.Struct("<4sQ")
MAX_NAME_BYTES = 1024  # fingerprints are 16 hex digits; publisher names are component names


class BadFrame(TransportError, ValueError):
    """Bytes on a key expression that are not an EMOS frame of the expected type."""


def _pad(n: int) -> int:
    return (-n) % 8


def frame_prefix(fingerprint: str, publisher_id: str) -> tuple[bytes, int]:
    """The constant part of a publisher's frames after the header, and the header's length.

    Computed once per publisher: only the stamp changes from message to message."""
    fp, pub = fingerprint.encode(), publisher_id.encode()
    if len(fp) > MAX_NAME_BYTES or len(pub) > MAX_NAME_BYTES:
        raise ValueError(f"publisher {publisher_id[:40]!r}: names on the network are at most {MAX_NAME_BYTES} bytes")
    head = _HEADER.size + len(fp) + len(pub)
    return fp + pub + b"\0" * _pad(head), head + _pad(head)


def write_frame(enc: codec.Encoded, stamp_ns: int, fingerprint: str, publisher_id: str, prefix: bytes, start: int, reuse: bytearray | None = None) -> bytearray:
    """One frame holding ``enc`` (one copy of the message, straight into the frame).

    ``reuse``: the previous frame, overwritten if it has the right size. Zenoh copies a frame
    when it is put, so the buffer is free again at once; reusing it spares the page faults of
    fresh memory on every message (6-7 ms per 8 MiB frame on this VM, 7x the copy itself)."""
    size = start + enc.nbytes
    frame = reuse if reuse is not None and len(reuse) == size else bytearray(size)
    _HEADER.pack_into(frame, 0, MAGIC, stamp_ns, len(fingerprint), len(publisher_id.encode()))
    frame[_HEADER.size : start] = prefix
    view = memoryview(frame)
    try:
        enc.write_into(view[start:])
    finally:
        view.release()
    return frame


class FrameWriter:
    """One publisher's frames: the constant part is built once, only the stamp and the message
    change. Small frames are joined into fresh ``bytes`` (one allocation, one C call); large ones
    are written into one reused buffer (see :func:`write_frame`)."""

    SMALL = 64 * 1024  # below this, joining beats writing into a kept buffer
    SPLIT = 64 * 1024  # arrays of this many bytes or more travel apart from the header (see split)

    def __init__(self, fingerprint: str, publisher_id: str):
        self.fingerprint, self.publisher_id = fingerprint, publisher_id
        self.prefix, self.start = frame_prefix(fingerprint, publisher_id)
        self._lengths = struct.pack("<HH", len(fingerprint.encode()), len(publisher_id.encode())) + self.prefix
        self.header = MAGIC + bytes(8) + self._lengths  # a whole frame's start, its stamp left to fill (see encode_framed)
        self._buffer: bytearray | None = None
        self._arrays: bytearray | None = None

    def frame(self, enc: codec.Encoded, stamp_ns: int) -> bytes | bytearray:
        """The frame of ``enc``; a large one is valid until the next call (put it before)."""
        if enc.array_bytes + len(enc.meta) < self.SMALL:  # enc.nbytes give or take its padding, without two property calls
            return b"".join([_MAGIC_STAMP.pack(MAGIC, stamp_ns), self._lengths, *enc.chunks()])
        frame = self._buffer = write_frame(enc, stamp_ns, self.fingerprint, self.publisher_id, self.prefix, self.start, self._buffer)
        return frame

    def split(self, enc: codec.Encoded, stamp_ns: int) -> tuple[bytes | bytearray, bytes]:
        """``(arrays, head)`` of a large message: its array region (the sample's payload) and
        the header with its metadata (the sample's attachment, magic ``"EMZ2"``).

        A message whose one array covers a whole ``bytes`` or ``bytearray`` (as every array a
        subscriber decodes does, and ``np.frombuffer(b)``) is sent from that object itself,
        with no copy of ours; any other array region is written into one reused buffer, valid
        until the next call (put it before)."""
        head = b"".join([_MAGIC_STAMP.pack(SPLIT_MAGIC, stamp_ns), self._lengths, *enc.head_chunks()])
        if len(enc.arrays) == 1:
            arr = enc.arrays[0]
            owner: object = arr.base  # numpy's stubs say ndarray | None; it is whatever owns the memory
            # C-contiguous (the encoder makes it so) and as long as its owner: it is the whole
            # object, first byte to last, so the object's bytes are the array's.
            if (type(owner) is bytes or type(owner) is bytearray) and len(owner) == arr.nbytes:
                return owner, head
        size = enc.array_bytes
        region = self._arrays if self._arrays is not None and len(self._arrays) == size else bytearray(size)
        self._arrays = region
        view = memoryview(region)
        try:
            enc.write_arrays_into(view)
        finally:
            view.release()
        return region, head


def read_message_python(data: Any, fingerprint: bytes, cls: type) -> tuple[int, str, Any]:
    """``(stamp_ns, publisher_id, message)`` of a whole frame: :func:`read_frame`, then the body
    decoded. Raises :class:`BadFrame` for the frame, :class:`emos.msgs.codec.DecodeError` for a
    body that does not decode (a well-framed lie)."""
    stamp, pub, payload = read_frame(data, fingerprint)
    return stamp, pub, codec.decode(cls, payload)


def _encode_unframed(msg: Any, header: bytes, stamp_ns: int, limit: int) -> codec.Encoded:
    return codec.encode(msg)


class SplitPayload:
    """A large message as it arrived in two parts: ``head`` (what :func:`read_frame` with
    ``magic=SPLIT_MAGIC`` returns of the sample's attachment: metadata length, metadata) and
    ``arrays`` (the sample's payload, the array region). Decoded by :meth:`decode`, which also
    checks that every array fits the region; the arrays are views of ``arrays``."""

    __slots__ = ("head", "arrays")

    def __init__(self, head: memoryview, arrays: bytes):
        self.head, self.arrays = head, arrays

    def decode(self, cls: type, copy: bool = False) -> Any:
        return codec.decode(cls, self.head, copy=copy, arrays=self.arrays)


def read_frame(data: Any, fingerprint: str | bytes, magic: bytes = MAGIC) -> tuple[int, str, memoryview]:
    """``(stamp_ns, publisher_id, payload)`` of a frame carrying messages of ``fingerprint``.

    Checks everything but the message body: magic, every length against the frame, the type
    fingerprint, the publisher's name, and that the message's own metadata length fits (see
    :func:`emos.msgs.codec.check_header`); decoding the body, which can still fail, is left to
    the caller. ``magic``: :data:`SPLIT_MAGIC` for the attachment of a message
    in two parts (the returned payload is then its metadata, see :class:`SplitPayload`).
    Cheap enough for Zenoh's delivery thread (about 1 us). Raises :class:`BadFrame` saying
    what is wrong; never reads outside ``data``."""
    fp = fingerprint if isinstance(fingerprint, bytes) else fingerprint.encode()
    size = len(data)
    if size < _HEADER.size:
        raise BadFrame(f"{size} B is shorter than a frame header ({_HEADER.size} B)")
    got_magic, stamp, fp_len, pub_len = _HEADER.unpack_from(data, 0)
    if got_magic != magic:
        if got_magic in (MAGIC, SPLIT_MAGIC):
            what = "a header with no array part" if got_magic == SPLIT_MAGIC else "a whole frame as the attachment"
            raise BadFrame(f"{what} (magic {bytes(got_magic)!r})")
        raise BadFrame(f"not an EMOS frame (starts with {bytes(got_magic)!r})")
    if fp_len > MAX_NAME_BYTES or pub_len > MAX_NAME_BYTES:
        raise BadFrame(f"names of {fp_len} and {pub_len} B exceed {MAX_NAME_BYTES} B")
    head = _HEADER.size + fp_len + pub_len
    start = head + _pad(head)
    if start > size:
        raise BadFrame(f"a {size} B frame announces a {start} B header")
    names = bytes(data[_LENGTHS_AT:head])  # both lengths, fingerprint, publisher: the same in every frame of a publisher
    pub = _checked.get((fp, names))
    if pub is None:
        pub = _check_names(names, fp_len, fp)
    try:
        codec.check_header(data, start)
    except codec.DecodeError as exc:
        raise BadFrame(f"publisher {pub[:60]!r}: {exc}") from None
    view = memoryview(data)
    return stamp, pub, (view if view.readonly else view.toreadonly())[start:]


# (expected fingerprint, the frame's name lengths + fingerprint + publisher) -> publisher name,
# for frames whose names passed the checks: a publisher's later frames need one lookup, not a
# decode and a comparison. Bounded: anyone can send frames with made-up names.
_LENGTHS_AT = _HEADER.size - 4
_checked: dict[tuple[bytes, bytes], str] = {}


def _check_names(names: bytes, fp_len: int, fp: bytes) -> str:
    try:
        pub = names[4 + fp_len :].decode()
    except UnicodeDecodeError as exc:
        raise BadFrame(f"names are not UTF-8: {exc}") from None
    if names[4 : 4 + fp_len] != fp:
        got = names[4 : 4 + fp_len].decode(errors="replace")
        raise BadFrame(f"publisher {pub[:60]!r} sends type fingerprint {got[:40]!r}, this subscriber expects {fp.decode()}")
    if len(_checked) >= 4096:
        _checked.clear()
    _checked[(fp, names)] = pub
    return pub


# The C fast path (see emos/msgs/_ccodec.c), when the codec has it: one C call for a publisher's
# whole small frame, and one for a whole frame's checks and decode. Both give the same results
# as the Python code here, which they fall back to (every bad frame, a publisher's first frame).
#   encode_framed(msg, FrameWriter.header, stamp_ns or None for now, FrameWriter.SMALL) -> the frame as bytes, or
#       the Encoded message for FrameWriter.frame or .split (always the latter without C);
#   read_message(data, fingerprint, cls) -> (stamp_ns, publisher, message), as read_message_python.
if codec.C_CODEC is not None:
    codec.C_CODEC.setup_frames(read_message_python, _checked)
    encode_framed, read_message = codec.C_CODEC.frame_message, codec.C_CODEC.read_message
else:
    encode_framed, read_message = _encode_unframed, read_message_python
