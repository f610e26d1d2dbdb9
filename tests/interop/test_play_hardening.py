"""`emos play` on hostile MCAP files (issue 31, items 5, 6, 14), against a real running system.

Every file is built here with the mcap library's writer and record classes, then damaged on
purpose: bytes flipped inside a chunk, decompression bombs, thousands of channels, topic names
EMOS cannot carry, a file that is not MCAP at all. `emos play` runs as the real CLI in a
subprocess; a subscriber in this process checks what reached the topic.
"""
from __future__ import annotations

import io
import os
import random
import signal
import subprocess
import sys
import threading
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mcap")

pytestmark = pytest.mark.process
zstandard = pytest.importorskip("zstandard")
lz4_frame = pytest.importorskip("lz4.frame")

from mcap.data_stream import ReadDataStream, RecordBuilder  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap.records import Channel, Chunk, DataEnd, Footer, Header, Message, Schema  # noqa: E402
from mcap.stream_reader import breakup_chunk  # noqa: E402
from mcap.writer import Writer  # noqa: E402

from emos.interop.mcap_bag import EMOS_ENCODING, EMOS_SCHEMA_ENCODING, BagInfo, BagWriter, ReadLimits, emos_schema, read_bag  # noqa: E402
from emos.interop.ros2_cdr import codec_for  # noqa: E402
from emos.msgs import Image, String, codec  # noqa: E402
from emos.msgs.registry import canonical_name  # noqa: E402
from emos.transport.context import SHM_DIR  # noqa: E402
from emos.transport.pubsub import Subscriber  # noqa: E402
from tests.runtime import helpers  # noqa: E402
from tests.runtime.helpers import SystemUnderTest, wait_until  # noqa: E402

MiB = 1 << 20
MCAP_MAGIC = b"\x89MCAP0\r\n"  # the MCAP spec's
RSS_CAP_KB = 300 * 1024  # generous: `emos play` itself needs about a third of it
HANG = 120.0  # bounds a hang only; nothing here should come near it

IDLE = """
class Idle(BaseComponent):
    def _execution_step(self):
        self.health_status.set_healthy()

idle = Idle(component_name="idle")
idle.config.loop_rate = 2.0
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[idle])
launcher.bringup()
"""


@pytest.fixture(scope="module")
def system(tmp_path_factory):
    """One idle system for the whole module: the files, not the system, are what each test varies."""
    sut = SystemUnderTest(tmp_path_factory.mktemp("system"), IDLE).wait_up(components=["idle"])
    helpers._STARTED.remove(sut)  # the per-test clean-up (conftest) would stop it after the first test
    yield sut
    sut.stop()


# -- running `emos play` -------------------------------------------------------------------------
# Runs a command as its child and writes the child's peak RSS (KiB) to argv[1]. A process forked
# from pytest and then exec'd reports at least pytest's own RSS at the fork as its peak (Linux
# carries the old memory's high-water mark across exec), which is about a gigabyte late in the
# suite; forked from this small interpreter, `emos play` reports its own. Signals are passed on.
PEAK_METER = r"""
import os, signal, sys
pid = os.fork()
if pid == 0:
    os.execv(sys.argv[2], sys.argv[2:])
for sig in (signal.SIGTERM, signal.SIGINT):
    signal.signal(sig, lambda s, _frame: os.kill(pid, s))
_, status, usage = os.wait4(pid, 0)
with open(sys.argv[1], "w") as f:
    f.write(str(usage.ru_maxrss))
code = os.waitstatus_to_exitcode(status)
os._exit(code if code >= 0 else 128 - code)
"""


class Play:
    """`emos play` in a subprocess, under PEAK_METER for its own peak RSS."""

    def __init__(self, tmp_path: Path, system: SystemUnderTest | None, *args: str):
        self.out_path, self.err_path = tmp_path / "play.out", tmp_path / "play.err"
        self.peak_path = tmp_path / "play.peak"
        run = ["--run", system.ctx.run_id] if system is not None else []
        with open(self.out_path, "w") as out, open(self.err_path, "w") as err:
            self.proc = subprocess.Popen([sys.executable, "-c", PEAK_METER, str(self.peak_path),
                                          sys.executable, "-m", "emos", "play", *run, *args],
                                         stdout=out, stderr=err, start_new_session=True)
        self.returncode: int | None = None
        self.maxrss_kb = 0

    def finish(self, timeout: float = HANG) -> Play:
        try:
            self.returncode = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            raise AssertionError(f"emos play did not end within {timeout} s\n{self.stdout}\n{self.stderr}") from None
        self.maxrss_kb = int(self.peak_path.read_text())
        return self

    @property
    def stdout(self) -> str:
        return self.out_path.read_text()

    @property
    def stderr(self) -> str:
        return self.err_path.read_text()

    def kill(self) -> None:
        """Kill the meter and `emos play` under it (one session)."""
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.proc.wait()


class Collector:
    """Takes every message of one topic, in a thread, while a play runs."""

    def __init__(self, system: SystemUnderTest, topic: str, cls: type):
        self.sub = Subscriber(system.ctx, topic, cls, queue_size=1000)
        self.got: list = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.got.extend(self.sub.take())
            time.sleep(0.002)

    def close(self) -> list:
        self._stop.set()
        self._thread.join()
        # What the player published after the thread's last take (it may have ended between two
        # takes): the rings are still mapped here.
        self.got.extend(self.sub.take())
        self.sub.close()
        return self.got


def own_segments(system: SystemUnderTest) -> list[os.stat_result]:
    """The run's /dev/shm segments (apparent sizes), the system's own included."""
    out = []
    for name in os.listdir(SHM_DIR):
        if name.startswith(system.ctx.shm_prefix):
            try:
                out.append(os.stat(SHM_DIR / name))
            except FileNotFoundError:
                pass
    return out


# -- building files ------------------------------------------------------------------------------
def frame(i: int) -> Image:
    rng = np.random.default_rng(i)  # noise: zstd cannot squeeze a chunk to nothing, so flips land in real data
    img = Image.from_numpy(rng.integers(0, 255, (20, 30, 3), dtype=np.uint8))
    img.header.frame_id = f"frame{i}"
    return img


def record(item) -> bytes:
    b = RecordBuilder()
    item.write(b)
    return bytes(b.end())


def chunk_record(inner: bytes, compression: str = "", declared: int | None = None, crc: int | None = None, data: bytes | None = None) -> bytes:
    if data is None:
        data = {"": inner, "zstd": zstandard.compress(inner) if compression == "zstd" else b"", "lz4": lz4_frame.compress(inner) if compression == "lz4" else b""}[compression]
    return record(Chunk(compression=compression, data=data, message_start_time=0, message_end_time=10**9,
                        uncompressed_crc=zlib.crc32(inner) if crc is None else crc,
                        uncompressed_size=len(inner) if declared is None else declared))


def string_file(path: Path, chunks: list[bytes], texts_first: list[str] = (), texts_last: list[str] = (), complete: bool = True) -> Path:
    """An MCAP file of /chatter String messages in plain chunks around ``chunks``, raw chunk
    records made by the test: complete (a footer, no summary) or as a killed recorder leaves it."""
    schema = Schema(id=1, name=canonical_name(String), encoding=EMOS_SCHEMA_ENCODING, data=emos_schema(String))
    channel = Channel(id=1, topic="/chatter", message_encoding=EMOS_ENCODING, schema_id=1, metadata={})

    def messages(texts, t0):
        return b"".join(record(Message(channel_id=1, sequence=k, log_time=t0 + k, publish_time=t0 + k, data=codec.pack(String(data=t))))
                        for k, t in enumerate(texts))

    body = [MCAP_MAGIC, record(Header(profile="", library="test")), record(schema), record(channel)]
    if texts_first:
        body.append(chunk_record(messages(texts_first, 1)))
    body += chunks
    if texts_last:
        body.append(chunk_record(messages(texts_last, 1000)))
    if complete:
        body += [record(DataEnd(0)), record(Footer(0, 0, 0)), MCAP_MAGIC]
    path.write_bytes(b"".join(body))
    return path


def zeros_compressed(n: int, compression: str, head: bytes) -> bytes:
    """``head`` and zeros up to ``n`` bytes in all, compressed without ever holding them (bomb material)."""
    pieces = [head, *(bytes(MiB) for _ in range((n - len(head)) // MiB)), bytes((n - len(head)) % MiB)]
    if compression == "zstd":
        c = zstandard.ZstdCompressor().compressobj()
        return b"".join([c.compress(p) for p in pieces] + [c.flush()])
    c = lz4_frame.LZ4FrameCompressor()
    return b"".join([c.begin()] + [c.compress(p) for p in pieces] + [c.flush()])


def message_claiming(size: int) -> bytes:
    """The start of chunk records ``size`` bytes long: one message on channel 1 claiming them all."""
    return bytes([5]) + (size - 9).to_bytes(8, "little") + (1).to_bytes(2, "little")


def unknown_record(size: int) -> bytes:
    """The start of chunk records ``size`` bytes long: one record of an opcode readers skip."""
    return bytes([0x80]) + (size - 9).to_bytes(8, "little")


# -- item 5: damaged chunks ------------------------------------------------------------------------
@pytest.mark.parametrize("compression", ["none", "zstd"])
def test_a_damaged_chunk_is_skipped_reported_and_never_played(system, tmp_path, compression):
    path = tmp_path / "camera.mcap"
    originals = {f"frame{i}": frame(i) for i in range(30)}
    with BagWriter(path, compression=compression, chunk_size=4096) as w:
        for i in range(30):
            w.write("/camera/rgb", originals[f"frame{i}"], publish_ns=10**9 + i * 20_000_000)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    index = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)[3]
    # 20 bytes flipped in the chunk's data (past its header), where the messages are.
    data = bytearray(path.read_bytes())
    start = index.chunk_start_offset + 9 + 8 * 3 + 4 + 4 + len(index.compression) + 8
    clean_chunk = bytes(data[index.chunk_start_offset + 9:index.chunk_start_offset + index.chunk_length])
    for pos in random.Random(5).sample(range(start + 64, index.chunk_start_offset + index.chunk_length - 8), 20):
        data[pos] ^= 0xFF
    path.write_bytes(bytes(data))
    # The frames that chunk held, by the mcap library's own reading of it before the damage.
    chunk = Chunk.read(ReadDataStream(io.BytesIO(clean_chunk)))
    cdr = codec_for("humble")  # Image is a type shared with ROS 2: recorded as cdr
    lost_ids = {cdr.deserialize(Image, m.data).header.frame_id for m in breakup_chunk(chunk) if isinstance(m, Message)}
    kept_ids = set(originals) - lost_ids
    assert lost_ids

    collector = Collector(system, "/camera/rgb", Image)
    try:
        play = Play(tmp_path, system, str(path)).finish()
    finally:
        got = collector.close()
    assert play.returncode == 0, play.stderr
    # Nothing corrupt reached the topic: every delivered image is one of the originals, intact.
    for img in got:
        original = originals.get(img.header.frame_id)
        assert original is not None, f"an image with a damaged frame_id {img.header.frame_id!r} was delivered"
        assert np.array_equal(img.to_numpy(), original.to_numpy()), f"{img.header.frame_id} was delivered corrupt"
    delivered = {img.header.frame_id for img in got}
    assert not delivered & lost_ids, "a message of the damaged chunk was played"
    assert delivered == kept_ids, "every message of the intact chunks is played"
    assert f"chunk at byte {index.chunk_start_offset}" in play.stderr and f"{len(lost_ids)} messages not played" in play.stderr
    assert f"1 damaged chunk skipped, {len(lost_ids)} messages in them not played" in play.stdout
    # The reader's own account, in-process.
    info = BagInfo()
    assert {m.decode().header.frame_id for m in read_bag(path, info=info)} == kept_ids
    assert len(info.damaged) == 1 and info.damaged[0].offset == index.chunk_start_offset and info.damaged[0].lost == len(lost_ids)


def test_a_chunk_with_a_wrong_crc_but_valid_looking_records_is_not_played(tmp_path):
    """Damage that leaves every record well formed: only the CRC can tell, and it must."""
    inner = b"".join(record(Message(channel_id=1, sequence=0, log_time=5, publish_time=5, data=codec.pack(String(data=t)))) for t in ("evil",))
    path = string_file(tmp_path / "crc.mcap", [chunk_record(inner, crc=zlib.crc32(inner) ^ 1)], ["before"], ["after"])
    info = BagInfo()
    texts = [m.decode().data for m in read_bag(path, info=info)]
    assert texts == ["before", "after"]
    assert len(info.damaged) == 1 and "CRC" in info.damaged[0].reason
    # A CRC of 0 means "not computed" (MCAP spec): such a chunk is read.
    path = string_file(tmp_path / "nocrc.mcap", [chunk_record(inner, crc=0)], ["before"], ["after"])
    assert [m.decode().data for m in read_bag(path)] == ["before", "evil", "after"]


# -- item 6: bounded resources -----------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["zstd-declared", "zstd-lying", "lz4-lying"])
def test_a_decompression_bomb_is_skipped_with_bounded_memory(system, tmp_path, kind):
    compression = kind.split("-")[0]
    actual = 1024 * MiB
    declared = actual if kind.endswith("declared") else 4096
    bomb = chunk_record(b"", compression, declared=declared, crc=0, data=zeros_compressed(actual, compression, message_claiming(actual)))
    # Cut short (no footer) as well as bombed: the oldest reader read such files (issue 31: 1 GB, minutes).
    path = string_file(tmp_path / "bomb.mcap", [bomb], ["before"], ["after"], complete=False)
    assert path.stat().st_size < 8 * MiB  # small file, 1 GiB inside
    collector = Collector(system, "/chatter", String)
    try:
        play = Play(tmp_path, system, str(path)).finish()
    finally:
        got = collector.close()
    assert play.maxrss_kb < RSS_CAP_KB, f"emos play peaked at {play.maxrss_kb // 1024} MB on a {path.stat().st_size // 1024} KB file"
    assert play.returncode == 0, play.stderr
    assert [m.data for m in got] == ["before", "after"]
    assert "damaged" in play.stderr and ("more than the limit" in play.stderr or "decompresses to more than" in play.stderr), play.stderr
    assert "1 damaged chunk skipped" in play.stdout


def test_sigterm_ends_the_play_while_it_reads_heavy_chunks(system, tmp_path):
    """4000 chunks of 64 MiB each (zeros, an unknown record): minutes of decompression in all,
    and no message among them for the play loop to notice a signal at."""
    # The chunk's records: one unknown record (opcode 0x80) spanning it, which readers skip.
    size = 64 * MiB
    heavy = chunk_record(b"", "zstd", declared=size, crc=0, data=zeros_compressed(size, "zstd", unknown_record(size)))
    path = string_file(tmp_path / "heavy.mcap", [heavy] * 4000, ["first"], complete=False)
    collector = Collector(system, "/chatter", String)
    play = Play(tmp_path, system, str(path))
    try:
        wait_until(lambda: collector.got, timeout=HANG, what="the first message (the play is then reading the heavy chunks)")
        play.proc.send_signal(signal.SIGTERM)
        play.finish(timeout=60)
    finally:
        play.kill()
        collector.close()
    assert play.returncode == 0, play.stderr
    assert "stopped by SIGTERM" in play.stdout
    assert play.maxrss_kb < RSS_CAP_KB


def many_topics_file(path: Path, n: int, gap_ns: int = 0) -> Path:
    with BagWriter(path, chunk_size=1 << 16) as w:
        for i in range(n):
            w.write(f"/t{i}", String(data=str(i)), publish_ns=10**9 + i * gap_ns)
    return path


def test_a_file_with_3000_topics_is_refused_and_nothing_is_created(system, tmp_path):
    path = many_topics_file(tmp_path / "many.mcap", 3000)
    assert path.stat().st_size < 1 * MiB
    before = len(own_segments(system))
    play = Play(tmp_path, system, str(path)).finish()
    assert play.returncode != 0
    assert "has 3000 topics to play, more than --max-topics 256" in play.stderr, play.stderr
    assert len(own_segments(system)) == before


def test_without_a_summary_at_most_max_topics_rings_are_made_each_sized_to_its_data(system, tmp_path):
    whole = many_topics_file(tmp_path / "many.mcap", 3000, gap_ns=1_000_000).read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole[: int(len(whole) * 0.8)])  # a killed recorder's file: no summary to count topics in
    baseline = {s.st_ino for s in own_segments(system)}
    play = Play(tmp_path, system, str(cut))
    peak_count, peak_bytes, largest = 0, 0, 0
    try:
        while play.proc.poll() is None:
            mine = [s for s in own_segments(system) if s.st_ino not in baseline]
            peak_count = max(peak_count, len(mine))
            peak_bytes = max(peak_bytes, sum(s.st_size for s in mine))
            largest = max([largest, *(s.st_size for s in mine)])
            time.sleep(0.05)
    finally:
        play.proc.wait(HANG)
    play.returncode = play.proc.returncode
    assert play.returncode == 0, play.stderr
    assert "cut short" in play.stdout
    assert "topics not played: over the limit of 256 topics" in play.stdout
    assert 0 < peak_count <= 256
    # A String of a few bytes needs a ring of a few KiB, not 1.1 MiB (18 slots of 64 KiB).
    assert largest <= 64 * 1024, largest
    assert peak_bytes <= 256 * 64 * 1024, peak_bytes


# -- item 14: names and file types -----------------------------------------------------------------
def test_topics_emos_cannot_carry_are_skipped_by_name_and_the_rest_plays(system, tmp_path):
    long_name = "/" + "x" * 598
    path = tmp_path / "names.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema(canonical_name(String), EMOS_SCHEMA_ENCODING, emos_schema(String))
        ids = {topic: w.register_channel(topic, EMOS_ENCODING, sid) for topic in ("/ok", "a b", long_name, "")}
        for k in range(3):
            for cid in ids.values():
                w.add_message(cid, log_time=k, publish_time=k, data=codec.pack(String(data=f"{k}")))
        w.finish()
    collector = Collector(system, "/ok", String)
    try:
        play = Play(tmp_path, system, str(path)).finish()
    finally:
        got = collector.close()
    assert play.returncode == 0, play.stderr
    assert "Traceback" not in play.stderr
    assert [m.data for m in got] == ["0", "1", "2"]
    assert "played 3 messages" in play.stdout
    for shown in ("'a b'", "''", "...(599 characters)"):
        assert shown in play.stdout, (shown, play.stdout)
    assert play.stderr.count("not playing") == 3, play.stderr  # one warning per bad topic
    assert not any("a b" in name or "xxxx" in name for name in os.listdir(SHM_DIR))


def test_a_text_file_is_not_an_mcap_file(tmp_path):
    path = tmp_path / "notes.mcap"
    path.write_text("these are my notes, not a recording\n" * 10)
    play = Play(tmp_path, None, str(path)).finish()
    assert play.returncode != 0
    assert f"{path} is not an MCAP file (expected magic" in play.stderr, play.stderr
    assert "cut short" not in play.stderr + play.stdout


def test_a_truncated_recording_still_says_cut_short(system, tmp_path):
    path = tmp_path / "cut.mcap"
    with BagWriter(path, chunk_size=1024) as w:
        for i in range(50):
            w.write("/chatter", String(data=str(i) * 50), publish_ns=10**9 + i)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    play = Play(tmp_path, system, str(path)).finish()
    assert play.returncode == 0, play.stderr
    assert "cut short" in play.stdout
    assert "not an MCAP file" not in play.stderr


# -- the reader in-process: CRCs outside chunks, records per chunk ---------------------------------
def test_summary_and_data_section_crcs_are_checked(tmp_path):
    path = tmp_path / "crcs.mcap"
    with open(path, "wb") as f:
        w = Writer(f, enable_data_crcs=True, chunk_size=1024)
        w.start()
        sid = w.register_schema(canonical_name(String), EMOS_SCHEMA_ENCODING, emos_schema(String))
        cid = w.register_channel("/chatter", EMOS_ENCODING, sid)
        for k in range(20):
            w.add_message(cid, log_time=k, publish_time=k, data=codec.pack(String(data="m" * 100)))
        w.finish()
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    info = BagInfo()
    assert len(list(read_bag(path, info=info))) == 20 and not info.problems and not info.damaged
    intact = path.read_bytes()
    # A byte of the first chunk's message index (between chunks: no chunk CRC covers it).
    first = min(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    data = bytearray(intact)
    data[first.chunk_start_offset + first.chunk_length + 20] ^= 0xFF
    path.write_bytes(bytes(data))
    info = BagInfo()
    assert len(list(read_bag(path, info=info))) == 20  # every chunk checks out by its own CRC
    assert any("data section fails its CRC" in p for p in info.problems), info.problems
    # A byte of a channel record in the summary: the summary is not trusted, the data section is.
    data = bytearray(intact)
    at = intact.rindex(b"/chatter")
    data[at + 1] ^= 0x20  # "/cHatter"
    path.write_bytes(bytes(data))
    info = BagInfo()
    assert {m.topic for m in read_bag(path, info=info)} == {"/chatter"}
    assert any("summary section fails its CRC" in p for p in info.problems), info.problems


def test_records_per_chunk_are_bounded(tmp_path):
    inner = b"".join(record(Message(channel_id=1, sequence=k, log_time=5, publish_time=5, data=codec.pack(String(data="x"))))
                     for k in range(50))
    path = string_file(tmp_path / "many.mcap", [chunk_record(inner)], ["before"], ["after"])
    info = BagInfo(limits=ReadLimits(max_chunk_records=20))
    assert [m.decode().data for m in read_bag(path, info=info)] == ["before", "after"]
    assert len(info.damaged) == 1 and "more than 20 records" in info.damaged[0].reason
    assert len(list(read_bag(path))) == 52  # the default limit lets it through


def test_a_damaged_record_length_skips_to_the_next_chunk_of_the_index(tmp_path):
    path = tmp_path / "framing.mcap"
    with BagWriter(path, chunk_size=1024) as w:
        for k in range(40):
            w.write("/chatter", String(data=f"{k:03d}" * 40), publish_ns=10**9 + k)
    with open(path, "rb") as f:
        chunks = sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    data = bytearray(path.read_bytes())
    data[chunks[2].chunk_start_offset + 8] ^= 0x7F  # the top byte of the chunk record's length
    path.write_bytes(bytes(data))
    info = BagInfo()
    texts = [m.decode().data for m in read_bag(path, info=info)]
    assert not info.truncated
    assert [d.offset for d in info.damaged] == [chunks[2].chunk_start_offset]
    assert any(f"skipped to the next chunk, at byte {chunks[3].chunk_start_offset}" in p for p in info.problems), info.problems
    # Everything but that chunk's messages, in order, up to the last.
    assert texts and len(texts) < 40 and texts == sorted(texts)
    assert texts[-1] == "039" * 40
