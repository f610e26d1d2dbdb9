"""Recordings of topics in MCAP files (https://mcap.dev), written and read with the ``mcap`` library.

Each topic is one MCAP channel, encoded the way the tools people already use understand:

* types shared with ROS 2 (see :mod:`emos.interop.ros2_cdr`): message encoding ``cdr``, schema
  encoding ``ros2msg`` holding the full concatenated definition, named with the ROS 2 type
  (``sensor_msgs/msg/Image``), exactly as rosbag2 writes them. Foxglove and ROS 2 tools read these.
* every other type: message encoding ``emos-msgpack`` (our own frame: msgpack tree + raw array
  bytes, see :mod:`emos.msgs.codec`) and schema encoding ``emos-msgpack-layout``: a JSON document
  naming the frame format, the EMOS type, its layout fingerprint and its fields, so a reader knows
  what the bytes are and whether its own class of that name still has the same layout.

Message ``publish_time`` is the publisher's stamp on the ring and ``log_time`` the moment the
recorder received it; playback follows ``publish_time``. Chunks are written straight to the file
as each fills, so a recorder killed without warning leaves a file readable up to its last
complete chunk (:func:`read_bag` reads such files, and says that it did).

Reading treats the file as untrusted: chunk, summary and data-section CRCs are checked (0 means
"not computed", as the MCAP specification says), a chunk's cost is bounded before it is paid
(:class:`ReadLimits`), a damaged chunk is skipped whole and reported, and channels whose topic
EMOS's own :class:`~emos.io.topic.Topic` would refuse are not played.
"""
from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any

import attrs
from attrs import define

# Reading is in its own module; its names are also this one's, for the callers of read_bag here.
from emos.interop.mcap_read import (  # noqa: F401
    EMOS_ENCODING,
    EMOS_SCHEMA_ENCODING,
    MCAP_MAGIC,
    BagChannel,
    BagInfo,
    BagMessage,
    DamagedChunk,
    NotMcapFile,
    ReadLimits,
    _mcap,
    read_bag,
    read_channels,
)
from emos.interop.ros2_cdr import DEFAULT_DISTRIBUTION, NotShared, codec_for
from emos.msgs import codec
from emos.msgs.registry import canonical_name

log = logging.getLogger("emos.interop")

COMPRESSIONS = ("none", "lz4", "zstd")
PROFILE = "ros2"  # the profile rosbag2 writes; our non-ROS channels are allowed extra encodings


def emos_schema(cls: type) -> bytes:
    """The self-description of an ``emos-msgpack`` channel's messages."""
    fields_ = []
    for f in attrs.fields(cls):
        nested = f.metadata.get("cls")
        fields_.append({"name": f.name, "kind": f.metadata.get("kind"), **({"type": canonical_name(nested())} if nested else {})})
    return json.dumps({
        "format": "EMOS message frame: u32 LE msgpack length, msgpack list of the fields in order, "
                  "arrays as msgpack ext 1 (dtype, shape, offset) into an 8-aligned raw array region",
        "type": canonical_name(cls),
        "fingerprint": cls._emos_fingerprint,  # type: ignore[attr-defined]
        "fields": fields_,
    }, indent=1).encode()


@define
class TopicStats:
    messages: int = 0
    bytes: int = 0


@define
class _Channel:
    id: int
    cdr: bool


class BagWriter:
    """Writes messages of many topics into one MCAP file.

    ``compression``: ``none`` (default, as rosbag2: the least CPU), ``zstd`` (about half the size
    for camera images, ~1 ms more CPU per 640x480 frame) or ``lz4`` (cheaper than zstd on
    compressible data, but it hardly shrinks camera noise). ``distribution``: the ROS 2 distribution whose type definitions the ``cdr``
    channels follow.
    """

    def __init__(self, path: str | os.PathLike[str], compression: str = "none", chunk_size: int = 1 << 20,
                 distribution: str = DEFAULT_DISTRIBUTION, metadata: dict[str, str] | None = None):
        mcap = _mcap()
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression must be one of {', '.join(COMPRESSIONS)}, got {compression!r}")
        if chunk_size < 1024:
            raise ValueError(f"chunk_size must be at least 1024 bytes, got {chunk_size}")
        self.path = Path(path)
        self.ros2 = codec_for(distribution)
        # Flushed whenever the writer emits a chunk (see write_frame), so a killed recorder
        # loses at most the chunk it was filling.
        self._file = open(self.path, "wb")  # noqa: SIM115 - the writer owns it until close()
        self._flushed_at = 0
        try:
            self._writer = mcap.writer.Writer(
                self._file, chunk_size=chunk_size,
                compression=getattr(mcap.writer.CompressionType, compression.upper()),
            )
            self._writer.start(profile=PROFILE, library="emos")
            self._writer.add_metadata("emos", {"ros_distribution": distribution, **(metadata or {})})
        except BaseException:
            self._file.close()
            raise
        self._schemas: dict[type, tuple[int, bool]] = {}
        self._channels: dict[tuple[str, type], _Channel] = {}
        self.stats: dict[str, TopicStats] = {}
        self._sequence = 0
        self.closed = False

    def _schema(self, cls: type) -> tuple[int, bool]:
        got = self._schemas.get(cls)
        if got is None:
            try:
                name = self.ros2.ros_type(cls)
                sid = self._writer.register_schema(name=name, encoding="ros2msg", data=self.ros2.message_definition(cls).encode())
                got = (sid, True)
            except NotShared:
                sid = self._writer.register_schema(name=canonical_name(cls), encoding=EMOS_SCHEMA_ENCODING, data=emos_schema(cls))
                got = (sid, False)
            self._schemas[cls] = got
        return got

    def channel(self, topic: str, cls: type) -> _Channel:
        ch = self._channels.get((topic, cls))
        if ch is None:
            sid, cdr = self._schema(cls)
            cid = self._writer.register_channel(
                topic=topic, message_encoding="cdr" if cdr else EMOS_ENCODING, schema_id=sid,
                metadata={"emos_type": canonical_name(cls)},
            )
            ch = self._channels[(topic, cls)] = _Channel(cid, cdr)
            self.stats.setdefault(topic, TopicStats())
        return ch

    def write_frame(self, topic: str, cls: type, frame: Any, publish_ns: int, log_ns: int) -> int:
        """Store one message given as an EMOS frame (what a subscriber reads); returns bytes written."""
        ch = self.channel(topic, cls)
        if ch.cdr:
            data: Any = self.ros2.serialize_view(codec.decode(cls, frame))
        else:
            data = frame  # the writer copies it into the chunk
        self._sequence += 1
        self._writer.add_message(channel_id=ch.id, log_time=log_ns, data=data, publish_time=publish_ns, sequence=self._sequence)
        pos = self._file.tell()  # moves only when a chunk was written out
        if pos != self._flushed_at:
            self._file.flush()
            self._flushed_at = pos
        st = self.stats[topic]
        st.messages += 1
        st.bytes += len(data)
        return len(data)

    def write(self, topic: str, msg: Any, publish_ns: int, log_ns: int | None = None) -> int:
        return self.write_frame(topic, type(msg), codec.pack(msg), publish_ns, publish_ns if log_ns is None else log_ns)

    @property
    def size(self) -> int:
        """Bytes in the file so far (complete chunks)."""
        return self._flushed_at if not self.closed else self.path.stat().st_size

    def close(self) -> None:
        """Write the summary and close the file (idempotent)."""
        if self.closed:
            return
        self.closed = True
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


