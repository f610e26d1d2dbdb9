"""Reading MCAP recordings (:func:`read_bag`), which are untrusted input.

A recording may come from a colleague, the internet or a crashed disk: the reader checks every
CRC the file carries (0 means "not computed", as the MCAP specification says), bounds what one
chunk may cost before it pays it (:class:`ReadLimits`), skips a damaged chunk whole and reports
it, and never hands out a message of a chunk that did not check out. Channels whose topic EMOS's
own :class:`~emos.io.topic.Topic` would refuse are not played. Writing is in
:mod:`emos.interop.mcap_bag`.
"""
from __future__ import annotations

import io
import json
import logging
import os
import struct
import zlib
from array import array
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import attrs
from attrs import define, field

from emos.config.validators import positive
from emos.errors import EmosError
from emos.interop.ros2_cdr import DEFAULT_DISTRIBUTION, NotShared, codec_for
from emos.io.topic import normalize_topic_name
from emos.msgs import codec
from emos.msgs.registry import UnknownMessageType, canonical_name, resolve

log = logging.getLogger("emos.interop")

EMOS_ENCODING = "emos-msgpack"  # our own message frame (emos.msgs.codec)
EMOS_SCHEMA_ENCODING = "emos-msgpack-layout"  # its schema: JSON naming the type, layout and fields


def _mcap() -> Any:
    try:
        import mcap.reader
        import mcap.stream_reader
        import mcap.writer
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError("recording needs the mcap package: pip install 'emos[ecosystem]'") from exc
    import mcap

    return mcap

# A recording is untrusted input (a file from a colleague, the internet, a crashed disk): the
# reader checks every CRC the file carries, bounds what one chunk may cost before it pays it,
# and never hands out a message of a chunk that did not check out. See ReadLimits.
MCAP_MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEADER = struct.Struct("<BQ")  # opcode, length of the body
_MESSAGE_HEADER = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
_CHUNK_FIXED = struct.Struct("<QQQII")  # start time, end time, uncompressed size, uncompressed CRC, compression length
_FOOTER = struct.Struct("<BQQQI")  # opcode, length (20), summary start, summary offset start, summary CRC
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_MESSAGE_INDEX = 1, 2, 3, 4, 5, 6, 7
_OP_CHUNK_INDEX, _OP_DATA_END = 0x08, 0x0F
_PIECE = 4 << 20  # bytes decompressed, checksummed or skipped per step, between looks at the stop flag
_STOP_EVERY = 4096  # records parsed between looks at the stop flag
# A chunk record holds its compressed data plus a header; compressed data may be a little larger
# than the raw data (incompressible input), so the record may exceed the chunk limit by this much.
_CHUNK_SLACK = 1 << 20
MiB = 1 << 20


class NotMcapFile(EmosError, ValueError):
    """The file does not start with the MCAP magic: it is something else, not a damaged recording."""


_COUNT = [attrs.validators.instance_of(int), positive]


@define(frozen=True)
class ReadLimits:
    """What reading one MCAP file may cost, whatever its headers claim.

    ``max_chunk_bytes``: decompressed size of one chunk (checked against the chunk's declared
    size before decompressing, and enforced while decompressing, so a header that lies cannot
    make it larger). ``max_chunk_records``: records in one chunk. ``max_topics``: topics one
    playback publishes (each is a shared-memory ring; see ``emos play --max-topics``).
    """

    max_chunk_bytes: int = field(default=256 * MiB, validator=_COUNT)
    max_chunk_records: int = field(default=1_000_000, validator=_COUNT)
    max_topics: int = field(default=256, validator=_COUNT)


@define
class BagChannel:
    topic: str
    cls: type | None  # None: a type we cannot decode, or a topic EMOS cannot carry (reason in ``problem``)
    encoding: str
    schema_name: str
    problem: str = ""
    largest: int = 0  # bytes of the largest message read so far (a whole chunk is read before any of it is played)


@define
class BagMessage:
    channel: BagChannel
    publish_ns: int
    log_ns: int
    data: bytes

    @property
    def topic(self) -> str:
        return self.channel.topic

    def decode(self, distribution: str = DEFAULT_DISTRIBUTION) -> Any:
        ch = self.channel
        if ch.cls is None:
            raise UnknownMessageType(f"topic {ch.topic}: {ch.problem}")
        if ch.encoding == "cdr":
            return codec_for(distribution).deserialize(ch.cls, self.data)
        return codec.decode(ch.cls, self.data, copy=True)


@define
class DamagedChunk:
    """A chunk :func:`read_bag` skipped: none of its messages were handed out."""

    offset: int  # of the chunk record in the file
    start_ns: int  # log time range the chunk header claims
    end_ns: int
    reason: str
    lost: int | None = None  # messages in it, from the file's message index (None: the file has none)

    def describe(self) -> str:
        lost = "an unknown number of messages" if self.lost is None else f"{self.lost} messages"
        return (f"chunk at byte {self.offset} (log time {self.start_ns / 1e9:.3f}..{self.end_ns / 1e9:.3f} s) "
                f"is damaged ({self.reason}): {lost} not played")


@define
class BagInfo:
    """What :func:`read_bag` found (channels by id, damage, whether the file was cut short), and
    what it reads under: ``limits`` and ``should_stop`` (polled between records and while
    decompressing; when it returns true, reading ends early with ``stopped`` set)."""

    channels: dict[int, BagChannel] = field(factory=dict)
    truncated: bool = False
    truncation_detail: str = ""
    messages: int = 0
    damaged: list[DamagedChunk] = field(factory=list)
    problems: list[str] = field(factory=list)  # file-level findings (CRCs, unreadable records), each logged once
    stopped: bool = False
    limits: ReadLimits = field(factory=ReadLimits)
    should_stop: Callable[[], bool] | None = None

    @property
    def lost(self) -> int:
        """Messages in damaged chunks (as far as the file's index tells)."""
        return sum(d.lost or 0 for d in self.damaged)


def _bag_channel(schema: Any, channel: Any, distribution: str) -> BagChannel:
    name = schema.name if schema is not None else ""
    enc = channel.message_encoding
    try:
        topic = normalize_topic_name(channel.topic)  # the rule every EMOS Topic follows
    except ValueError as exc:
        return BagChannel(channel.topic, None, enc, name, f"not a topic name EMOS can carry: {exc}")
    if enc == "cdr":
        try:
            cls = codec_for(distribution).class_for(name)
        except NotShared as exc:
            return BagChannel(topic, None, enc, name, f"ROS 2 type {name} is not one EMOS shares ({exc})")
        return BagChannel(topic, cls, enc, name)
    if enc == EMOS_ENCODING:
        try:
            cls = resolve(name)
        except UnknownMessageType as exc:
            return BagChannel(topic, None, enc, name, str(exc))
        try:
            recorded = json.loads(schema.data).get("fingerprint")
        except (ValueError, AttributeError):
            recorded = None
        if recorded != cls._emos_fingerprint:  # type: ignore[attr-defined]
            return BagChannel(topic, None, enc, name, f"{name} was recorded with a different field layout than this EMOS defines")
        return BagChannel(topic, cls, enc, name)
    return BagChannel(topic, None, enc, name, f"message encoding {enc!r} is not one EMOS reads (cdr, {EMOS_ENCODING})")


def read_bag(path: str | os.PathLike[str], topics: list[str] | None = None, info: BagInfo | None = None,
             distribution: str = DEFAULT_DISTRIBUTION) -> Iterator[BagMessage]:
    """Messages of an MCAP file, chunk by chunk in file order (by log time within a chunk).

    Every chunk is checked before any of its messages is handed out: its CRC (when the writer
    computed one), its declared and actual decompressed size against ``info.limits``, and the
    framing of its records. A chunk that fails is skipped, logged once and listed in
    ``info.damaged``. A file cut short (no footer: the recorder was killed) is read up to its
    last complete record; ``info.truncated`` then says so. A file that is not MCAP at all raises
    :class:`NotMcapFile`.
    """
    _mcap()
    info = info if info is not None else BagInfo()
    wanted = set(topics) if topics else None
    with open(path, "rb") as f:
        yield from _BagReader(f, info, distribution, wanted).messages()


def read_channels(path: str | os.PathLike[str], info: BagInfo | None = None, distribution: str = DEFAULT_DISTRIBUTION) -> dict[int, BagChannel]:
    """The channels a file's summary lists (empty for a file without a usable summary), without
    reading its data; raises :class:`NotMcapFile` for a file that is not MCAP."""
    _mcap()
    info = info if info is not None else BagInfo()
    with open(path, "rb") as f:
        reader = _BagReader(f, info, distribution, None)
        reader.log_problems = False  # in info.problems; the pass that reads the messages logs them
        reader.check_magic()
        reader.load_summary()
    return info.channels


class _ChunkDamage(EmosError):
    """Why a chunk cannot be trusted (the message names the problem)."""


class _BagReader:
    """One pass over one file; see :func:`read_bag`."""

    def __init__(self, f: Any, info: BagInfo, distribution: str, wanted: set[str] | None):
        self.f = f
        self.name = getattr(f, "name", "MCAP file")
        self.size = os.fstat(f.fileno()).st_size
        self.info = info
        self.limits = info.limits
        self.should_stop = info.should_stop or (lambda: False)
        self.distribution = distribution
        self.wanted = wanted
        self.schemas: dict[int, Any] = {}
        self.topic_owner: dict[str, BagChannel] = {}  # the channel whose type a topic is played with
        self.shadowed: set[int] = set()  # channels of a topic another channel already plays with another type
        self.footer_ok = False
        self.chunk_index: dict[int, tuple[int, int]] = {}  # intact summary's chunks: offset -> log time range
        self.pending: DamagedChunk | None = None  # a damaged chunk whose message index may follow
        self.unknown_channel = 0
        self.log_problems = True

    # -- file structure ----------------------------------------------------------------------------
    def check_magic(self) -> bool:
        """False for a file cut inside its magic; raises NotMcapFile for anything else that is not MCAP."""
        head = self.f.read(len(MCAP_MAGIC))
        if head == MCAP_MAGIC:
            return True
        if head and MCAP_MAGIC.startswith(head):
            return False
        raise NotMcapFile(f"{self.name} is not an MCAP file (expected magic {MCAP_MAGIC!r} at its start, "
                          f"found {head[:len(MCAP_MAGIC)]!r}{' (the file is empty)' if not head else ''})")

    def problem(self, text: str) -> None:
        self.info.problems.append(text)
        if self.log_problems:
            log.warning("%s: %s", self.name, text)

    def load_summary(self) -> None:
        """Channels and schemas from the summary section, if the file has an intact one."""
        mcap = _mcap()
        footer_at = self.size - len(MCAP_MAGIC) - _FOOTER.size
        if footer_at < len(MCAP_MAGIC):
            return
        self.f.seek(footer_at)
        tail = self.f.read(_FOOTER.size + len(MCAP_MAGIC))
        if tail[_FOOTER.size:] != MCAP_MAGIC:
            return  # no footer: cut short (the stream pass finds out where)
        op, length, start, _offsets, crc = _FOOTER.unpack(tail[:_FOOTER.size])
        if op != _OP_FOOTER or length != 20:
            return
        self.footer_ok = True
        if start == 0:
            return  # a complete file without a summary section
        if not len(MCAP_MAGIC) <= start <= footer_at:
            self.problem(f"the footer points its summary at byte {start}, outside the file: ignoring the summary")
            return
        if footer_at - start > self.limits.max_chunk_bytes:
            self.problem(f"the summary section is {footer_at - start} bytes, more than the limit of {self.limits.max_chunk_bytes}: ignoring it")
            return
        self.f.seek(start)
        data = self.f.read(footer_at - start)
        if crc and zlib.crc32(tail[:_FOOTER.size - 4], zlib.crc32(data)) != crc:
            self.problem("the summary section fails its CRC: ignoring it (channels come from the data section)")
            return
        try:
            for op, p, length in self._records(data, "summary section"):
                if op == _OP_SCHEMA:
                    self._add_schema(mcap.records.Schema.read(_stream(data[p:p + length])))
                elif op == _OP_CHANNEL:
                    self._add_channel(mcap.records.Channel.read(_stream(data[p:p + length])))
                elif op == _OP_CHUNK_INDEX and length >= 24:
                    start_ns, end_ns, offset = struct.unpack_from("<QQQ", data, p)
                    self.chunk_index[offset] = (start_ns, end_ns)
        except (_ChunkDamage, ValueError, EOFError, struct.error, mcap.exceptions.McapError) as exc:
            self.problem(f"the summary section is damaged ({exc}): channels it lists after the damage come from the data section")

    def _records(self, data: Any, where: str) -> Iterator[tuple[int, int, int]]:
        """(opcode, body start, body length) of the records in ``data``; raises _ChunkDamage on
        broken framing or too many records."""
        p, n, count = 0, len(data), 0
        while p < n:
            if n - p < _RECORD_HEADER.size:
                raise _ChunkDamage(f"a record header at byte {p} of the {where} is cut off")
            op, length = _RECORD_HEADER.unpack_from(data, p)
            p += _RECORD_HEADER.size
            if length > n - p:
                raise _ChunkDamage(f"a record at byte {p - _RECORD_HEADER.size} of the {where} claims {length} bytes, {n - p} remain")
            count += 1
            if count > self.limits.max_chunk_records:
                raise _ChunkDamage(f"the {where} holds more than {self.limits.max_chunk_records} records (the limit)")
            yield op, p, length
            p += length

    def _add_schema(self, record: Any) -> None:
        self.schemas.setdefault(record.id, record)

    def _add_channel(self, record: Any) -> None:
        if record.id in self.info.channels:
            return  # first definition wins (the summary's, read first, is CRC-checked)
        ch = _bag_channel(self.schemas.get(record.schema_id), record, self.distribution)
        owner = self.topic_owner.get(ch.topic)
        if ch.cls is not None and owner is not None and owner.cls is not ch.cls:
            self.shadowed.add(record.id)
            self.problem(f"topic {ch.topic} is recorded as {canonical_name(owner.cls)} and as {canonical_name(ch.cls)} "  # type: ignore[arg-type]
                         f"(channel {record.id}): a topic carries one type, so channel {record.id} is not read")
        elif ch.cls is not None and owner is None:
            self.topic_owner[ch.topic] = ch
        self.info.channels[record.id] = ch

    # -- the data section --------------------------------------------------------------------------
    def messages(self) -> Iterator[BagMessage]:
        if not self.check_magic():
            self._cut_short("the file ends inside the MCAP magic")
            return
        self.load_summary()
        self.f.seek(len(MCAP_MAGIC))
        crc = zlib.crc32(MCAP_MAGIC)  # of the data section, for the DataEnd record's CRC
        resynced = False  # skipped bytes after broken framing: that CRC cannot be checked any more
        pos = len(MCAP_MAGIC)
        ended = ""  # why the pass stopped before a DataEnd or Footer record
        while True:
            if self.should_stop():
                self._stopped()
                return
            head = self.f.read(_RECORD_HEADER.size)
            if len(head) < _RECORD_HEADER.size:
                ended = "reading stopped at an incomplete record" if head else ""
                break
            op, length = _RECORD_HEADER.unpack(head)
            if length > self.size - pos - len(head):
                ended = f"the record at byte {pos} claims {length} bytes, past the end of the file"
                resume = min((c for c in self.chunk_index if c > pos), default=None)
                if resume is None:
                    break
                # Framing is lost (a damaged length field); the summary's index says where the
                # next chunk starts. The data-section CRC cannot be checked past this point.
                self._flush_damage()
                if pos in self.chunk_index:
                    self.pending = DamagedChunk(pos, *self.chunk_index[pos], "its record length is damaged")
                    self._flush_damage()
                self.problem(f"{ended}: skipped to the next chunk, at byte {resume}")
                self.f.seek(resume)
                pos, ended, resynced = resume, "", True
                continue
            if op != _OP_MESSAGE_INDEX:
                self._flush_damage()
            if op == _OP_DATA_END:
                body = self.f.read(length)
                stored = struct.unpack_from("<I", body)[0] if len(body) >= 4 else 0
                if stored and not resynced and stored != crc:
                    self.problem("the data section fails its CRC: bytes outside the chunks' own checks (chunk headers, "
                                 "indexes, records between chunks) were altered")
                break
            if op == _OP_FOOTER:
                break
            limit = self.limits.max_chunk_bytes + (_CHUNK_SLACK if op == _OP_CHUNK else 0)
            if op not in (_OP_CHUNK, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_MESSAGE_INDEX) or length > limit:
                first = self.f.read(min(length, 16))  # a chunk's time range, for the report
                skipped = self._skip(length - len(first), zlib.crc32(first, zlib.crc32(head, crc)))  # attachments, metadata, indexes: not needed to play
                if skipped is None:
                    self._stopped()
                    return
                crc = skipped
                if op == _OP_CHUNK:
                    self.pending = DamagedChunk(pos, *_chunk_times(first), f"its record is {length} bytes, more than the limit of {limit} (--max-chunk-mb)")
                elif length > limit and op in (_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE):
                    self.problem(f"the record at byte {pos} is {length} bytes, more than the limit of {limit}: skipped")
                pos += len(head) + length
                continue
            body = self.f.read(length)
            crc = zlib.crc32(body, zlib.crc32(head, crc))
            try:
                if op == _OP_CHUNK:
                    yield from self._chunk(pos, body)
                elif op == _OP_MESSAGE_INDEX:
                    self._count_lost(body)
                else:
                    yield from self._top_level(op, body)
            except _Stopped:
                self._stopped()
                return
            pos += len(head) + length
        self._flush_damage()
        if self.unknown_channel:
            self.problem(f"{self.unknown_channel} messages name a channel the file never defines: not played")
        if ended and self.footer_ok:
            self.problem(f"the data section is damaged ({ended}): the rest of it was not read")
        elif ended or not self.footer_ok:
            self._cut_short("the file ends without a summary section" + (f"; {ended}" if ended else ""))

    def _stopped(self) -> None:
        self.info.stopped = True
        self._flush_damage()

    def _cut_short(self, reason: str) -> None:
        self.info.truncated = True
        self.info.truncation_detail = reason
        log.warning("%s is incomplete (%s: was the recorder killed?); read %d messages up to the last complete chunk",
                    self.name, reason, self.info.messages)

    def _skip(self, length: int, crc: int) -> int | None:
        """Read past ``length`` bytes in pieces (keeping the data CRC); None if told to stop meanwhile."""
        while length > 0:
            if self.should_stop():
                return None
            piece = self.f.read(min(length, _PIECE))
            if not piece:
                break
            crc = zlib.crc32(piece, crc)
            length -= len(piece)
        return crc

    def _top_level(self, op: int, body: memoryview | bytes) -> Iterator[BagMessage]:
        mcap = _mcap()
        try:
            if op == _OP_SCHEMA:
                self._add_schema(mcap.records.Schema.read(_stream(body)))
            elif op == _OP_CHANNEL:
                self._add_channel(mcap.records.Channel.read(_stream(body)))
            elif op == _OP_MESSAGE:
                if len(body) < _MESSAGE_HEADER.size:
                    raise ValueError(f"a message record of {len(body)} bytes is shorter than its header")
                got = self._message(memoryview(body), 0, len(body))
                if got is not None:
                    yield got
        except (ValueError, EOFError, struct.error, mcap.exceptions.McapError) as exc:
            self.problem(f"a damaged record outside chunks was skipped ({exc})")

    def _message(self, view: memoryview, p: int, length: int) -> BagMessage | None:
        cid, _seq, log_ns, pub_ns = _MESSAGE_HEADER.unpack_from(view, p)
        ch = self.info.channels.get(cid)
        if ch is None:
            self.unknown_channel += 1
            return None
        if cid in self.shadowed or (self.wanted is not None and ch.topic not in self.wanted):
            return None
        self.info.messages += 1
        return BagMessage(ch, pub_ns, log_ns, bytes(view[p + _MESSAGE_HEADER.size:p + length]))

    # -- chunks -----------------------------------------------------------------------------------
    def _chunk(self, offset: int, body: bytes) -> Iterator[BagMessage]:
        try:
            start, end, raw = self._open_chunk(body)
        except _ChunkDamage as exc:
            start, end = _chunk_times(body)
            self.pending = DamagedChunk(offset, start, end, str(exc))
            return
        try:
            order, where = self._scan_chunk(raw)
        except _ChunkDamage as exc:
            self.pending = DamagedChunk(offset, start, end, str(exc))
            return
        for k, i in enumerate(order):
            if k % _STOP_EVERY == _STOP_EVERY - 1 and self.should_stop():
                raise _Stopped
            got = self._message(raw, where[2 * i], where[2 * i + 1])
            if got is not None:
                yield got

    def _open_chunk(self, body: bytes) -> tuple[int, int, memoryview]:
        """(start, end, raw records) of a chunk that passes its size and CRC checks."""
        if len(body) < _CHUNK_FIXED.size:
            raise _ChunkDamage("its header is cut off")
        start, end, size, crc, clen = _CHUNK_FIXED.unpack_from(body)
        p = _CHUNK_FIXED.size
        if clen > 64 or len(body) < p + clen + 8:
            raise _ChunkDamage("its header is malformed")
        compression = bytes(body[p:p + clen]).decode("utf-8", "replace")
        (dlen,) = struct.unpack_from("<Q", body, p + clen)
        p += clen + 8
        if dlen != len(body) - p:
            raise _ChunkDamage(f"it says it holds {dlen} bytes of data, its record holds {len(body) - p}")
        if size > self.limits.max_chunk_bytes:
            raise _ChunkDamage(f"it declares {size} bytes decompressed, more than the limit of {self.limits.max_chunk_bytes} (--max-chunk-mb)")
        raw = self._decompress(compression, memoryview(body)[p:], size)
        if len(raw) > size:
            raise _ChunkDamage(f"it decompresses to more than the {size} bytes its header declares")
        if len(raw) < size:
            raise _ChunkDamage(f"it decompresses to {len(raw)} bytes, its header declares {size}")
        if crc and zlib.crc32(raw) != crc:
            raise _ChunkDamage(f"its CRC does not match (stored {crc:#010x}, computed {zlib.crc32(raw):#010x})")
        return start, end, memoryview(raw)

    def _decompress(self, compression: str, data: memoryview, size: int) -> bytes | bytearray | memoryview:
        """At most ``size + 1`` bytes of the chunk's data (one more shows a header that lies)."""
        if compression == "":
            return data
        out = bytearray()
        bound = size + 1
        try:
            if compression == "zstd":
                import zstandard

                reader = zstandard.ZstdDecompressor().stream_reader(data, read_across_frames=True)
                while len(out) < bound:
                    if self.should_stop():
                        raise _Stopped
                    piece = reader.read(min(_PIECE, bound - len(out)))
                    if not piece:
                        break
                    out += piece
            elif compression == "lz4":
                import lz4.frame

                rest: Any = data
                while len(out) < bound and rest:
                    dec = lz4.frame.LZ4FrameDecompressor()
                    while len(out) < bound:
                        if self.should_stop():
                            raise _Stopped
                        out += dec.decompress(rest, max_length=min(_PIECE, bound - len(out)))
                        rest = b""
                        if dec.eof or dec.needs_input:
                            break
                    rest = dec.unused_data if dec.eof else b""
            else:
                raise _ChunkDamage(f"its compression {compression!r} is not one EMOS reads (zstd, lz4, none)")
        except (_ChunkDamage, _Stopped):
            raise
        except Exception as exc:  # zstandard.ZstdError, RuntimeError of lz4: the data is not what it claims
            raise _ChunkDamage(f"its {compression} data does not decompress ({exc})") from exc
        return out

    def _scan_chunk(self, raw: memoryview) -> tuple[Iterable[int], array[int]]:
        """Check a chunk's records and take in its schemas and channels. Returns the order to play
        its messages in and their (offset, length) pairs, flat; nothing at all if any record is
        malformed."""
        mcap = _mcap()
        where = array("Q")  # offset, length of each message record's body (8 bytes each, not a tuple)
        times = array("Q")
        schemas, channels = [], []
        largest: dict[int, int] = {}
        try:
            for k, (op, p, length) in enumerate(self._records(raw, "chunk")):
                if k % _STOP_EVERY == _STOP_EVERY - 1 and self.should_stop():
                    raise _Stopped
                if op == _OP_MESSAGE:
                    if length < _MESSAGE_HEADER.size:
                        raise _ChunkDamage(f"a message record of {length} bytes is shorter than its header")
                    cid, _seq, log_ns, _pub = _MESSAGE_HEADER.unpack_from(raw, p)
                    where.append(p)
                    where.append(length)
                    times.append(log_ns)
                    n = length - _MESSAGE_HEADER.size
                    if n > largest.get(cid, 0):
                        largest[cid] = n
                elif op == _OP_SCHEMA:
                    schemas.append(mcap.records.Schema.read(_stream(raw[p:p + length])))
                elif op == _OP_CHANNEL:
                    channels.append(mcap.records.Channel.read(_stream(raw[p:p + length])))
        except (ValueError, EOFError, struct.error, mcap.exceptions.McapError) as exc:
            raise _ChunkDamage(f"a record in it is malformed ({exc})") from exc
        for s in schemas:
            self._add_schema(s)
        for c in channels:
            self._add_channel(c)
        for cid, n in largest.items():
            ch = self.info.channels.get(cid)
            if ch is not None and n > ch.largest:
                ch.largest = n
        if all(a <= b for a, b in zip(times, times[1:])):
            return range(len(times)), where
        import numpy as np

        return np.argsort(np.frombuffer(times, dtype=np.uint64), kind="stable").tolist(), where

    def _count_lost(self, body: bytes) -> None:
        """A message index record after a damaged chunk: how many messages that chunk held."""
        if self.pending is None or len(body) < 6:
            return
        (records,) = struct.unpack_from("<I", body, 2)
        self.pending.lost = (self.pending.lost or 0) + records // 16

    def _flush_damage(self) -> None:
        if self.pending is not None:
            damaged, self.pending = self.pending, None
            self.info.damaged.append(damaged)
            log.warning("%s: %s", self.name, damaged.describe())


class _Stopped(EmosError):
    """``should_stop()`` said so while a chunk was being read."""


def _stream(body: Any) -> Any:
    from mcap.data_stream import ReadDataStream

    return ReadDataStream(io.BytesIO(body))


def _chunk_times(body: bytes) -> tuple[int, int]:
    return struct.unpack_from("<QQ", body) if len(body) >= 16 else (0, 0)
