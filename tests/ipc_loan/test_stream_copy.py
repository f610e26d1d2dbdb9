"""Big arrays are copied into ring slots with streaming (non-temporal) stores (issue 34, 8 MiB):
the C copy writes exactly the bytes numpy would, the frames do not change, the Python codec
(no compiler) still writes them alone, and a writer SIGKILLed in the middle of a streaming copy
never leaves a torn message visible (the copy's fences keep the ring's seqlock). Where streaming
starts depends on the machine's last-level cache (``codec.stream_min_bytes``, tested at the end);
the tests of the mechanism pin it to 128 KiB (``FLOOR``), so they stream on every machine."""
import mmap
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from emos import msgs as M
from emos.msgs import codec
from emos.transport import pubsub
from emos.transport.context import RunContext
from emos.transport.pubsub import Publisher, Subscriber
from tests.ipc_loan.torn import sigkill_writer_and_check

needs_c = pytest.mark.skipif(codec._stream_copy is None, reason="the codec's C extension is not built here (the Python codec alone)")
FLOOR = 128 * 1024  # the threshold these tests stream from, whatever the machine's cache


@pytest.fixture
def streaming_from_floor(monkeypatch):
    """Stream from FLOOR in this process and in writers forked from it."""
    monkeypatch.setattr(codec, "STREAM_MIN_BYTES", FLOOR)


@needs_c
@pytest.mark.unit
@pytest.mark.parametrize("size", [0, 1, 15, 63, 64, 65, 127, 1000, 4096 + 17, (1 << 20) + 3])
@pytest.mark.parametrize("offset", [0, 1, 8, 32, 63, 64])
def test_stream_copy_writes_exactly_the_source_and_nothing_around_it(size, offset):
    src = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8)
    mm = mmap.mmap(-1, offset + size + 128)  # shared memory, as a ring slot is
    mm.write(b"\xee" * len(mm))
    end = codec._stream_copy(mm, offset, src)
    assert end == offset + size
    dst = np.frombuffer(mm, np.uint8)
    assert np.array_equal(dst[offset : offset + size], src)
    assert (dst[:offset] == 0xEE).all() and (dst[offset + size :] == 0xEE).all()
    del dst
    mm.close()


@needs_c
@pytest.mark.unit
def test_stream_copy_refuses_what_does_not_fit_and_read_only_destinations():
    buf = bytearray(100)
    with pytest.raises(ValueError, match="do not fit a destination of 100 B"):
        codec._stream_copy(buf, 90, np.zeros(11, np.uint8))
    with pytest.raises(ValueError, match="offset -1"):
        codec._stream_copy(buf, -1, np.zeros(1, np.uint8))
    with pytest.raises(BufferError):
        codec._stream_copy(bytes(100), 0, np.zeros(1, np.uint8))
    with pytest.raises((BufferError, ValueError)):  # the caller passes contiguous bytes only
        codec._stream_copy(buf, 0, np.zeros((4, 4), np.uint8)[:, ::2])
    assert buf == bytearray(100)


def _streamed(enc: codec.Encoded) -> bytes:
    """The frame as a publisher writes it into a ring slot (shared memory, streaming stores)."""
    mm = mmap.mmap(-1, enc.nbytes + 64)  # zeros, as to_bytes starts from (write_into skips the padding)
    mm[enc.nbytes :] = b"\xee" * 64
    assert enc.write_into(memoryview(mm)[: enc.nbytes], stream=True) == enc.nbytes
    frame = mm[: enc.nbytes]
    assert mm[enc.nbytes :] == b"\xee" * 64
    mm.close()
    return frame


@needs_c
@pytest.mark.unit
def test_frames_with_streamed_arrays_are_byte_for_byte_the_numpy_ones(streaming_from_floor):
    rng = np.random.default_rng(7)
    msg = M.PointCloud2(
        height=1, width=3, point_step=4, row_step=12,
        data=rng.integers(0, 256, 300_001, dtype=np.uint8),
    )
    img = M.Image.from_numpy(rng.integers(0, 256, (480, 640, 3), dtype=np.uint8))
    # Two big arrays, the first of an odd length: the second starts at an offset streamed to.
    scan = M.LaserScan(ranges=rng.standard_normal(70_001).astype(np.float32), intensities=rng.standard_normal(40_003).astype(np.float32))
    assert scan.ranges.nbytes >= codec.STREAM_MIN_BYTES and msg.data.nbytes >= codec.STREAM_MIN_BYTES
    for m, field in ((msg, "data"), (img, "data"), (scan, "ranges"), (scan, "intensities")):
        enc = codec.encode(m)
        streamed = _streamed(enc)
        assert streamed == enc.to_bytes() == b"".join(bytes(c) for c in enc.chunks())
        back = codec.decode(type(m), streamed)
        assert np.array_equal(getattr(back, field), getattr(m, field))


@pytest.mark.process
def test_the_python_codec_alone_writes_the_same_frames():
    """Without the C extension (no compiler: its import fails) big arrays are copied by numpy."""
    code = r"""
import sys
class NoCCodec:
    def find_spec(self, name, path=None, target=None):
        if name == "emos.msgs._ccodec":
            raise ImportError("no compiler here")
sys.meta_path.insert(0, NoCCodec())
import zlib
import numpy as np
from emos import msgs as M
from emos.msgs import codec
assert codec.C_CODEC is None and codec._stream_copy is None
data = np.random.default_rng(1).integers(0, 256, 128 * 1024 + 11, dtype=np.uint8)
frame = codec.encode(M.UInt8MultiArray(data=data)).to_bytes()
assert np.array_equal(codec.decode(M.UInt8MultiArray, frame).data, data)
print(zlib.crc32(frame))
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    data = np.random.default_rng(1).integers(0, 256, FLOOR + 11, dtype=np.uint8)
    assert int(done.stdout) == zlib.crc32(codec.encode(M.UInt8MultiArray(data=data)).to_bytes())


@pytest.mark.unit
def test_a_published_message_past_the_threshold_arrives_intact(ctx, streaming_from_floor, ring_path):
    sub = Subscriber(ctx, "/big", M.UInt8MultiArray, queue_size=4)
    pub = Publisher(ctx, "/big", M.UInt8MultiArray, publisher_id="big", depth=2)
    rng = np.random.default_rng(3)
    sent = [rng.integers(0, 256, codec.STREAM_MIN_BYTES + k, dtype=np.uint8) for k in (0, 5, 64)]
    for data in sent:
        pub.publish(M.UInt8MultiArray(data=data))
        [got] = sub.take()
        assert np.array_equal(got.data, data)
        del got
    sub.close()
    pub.close()


@needs_c
@pytest.mark.unit
@pytest.mark.parametrize("path", ["c", "python"])
def test_a_publisher_streams_big_arrays_into_its_ring_and_copies_small_ones(ctx, monkeypatch, streaming_from_floor, path):
    """Both of the publisher's paths for big frames: one C call (``_ccodec.ring_write``, which
    counts what it streams) and the Python one (``codec._stream_copy``, counted here)."""
    calls = []
    real = codec._stream_copy

    def counting(dst, offset, src):
        calls.append(src.nbytes)
        return real(dst, offset, src)

    monkeypatch.setattr(codec, "_stream_copy", counting)
    if path == "python":
        monkeypatch.setattr(pubsub, "_ring_write", None)
    sub = Subscriber(ctx, "/cam", M.Image, queue_size=4)
    pub = Publisher(ctx, "/cam", M.Image, publisher_id="cam", depth=2)
    frame = np.random.default_rng(5).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    before = codec.C_CODEC.streamed()
    pub.publish(M.Image.from_numpy(frame))
    pub.publish(M.Image.from_numpy(frame[:8, :8]))  # 192 B: a plain copy
    got = sub.take()
    streamed = codec.C_CODEC.streamed() - before
    if path == "c":
        assert (calls, streamed) == ([], frame.nbytes if codec.C_CODEC.STREAM_STORES else 0)
    else:
        assert (calls, streamed) == ([frame.nbytes], 0)
    assert np.array_equal(got[0].to_numpy(), frame) and np.array_equal(got[1].to_numpy(), frame[:8, :8])
    del got
    sub.close()
    pub.close()


def _streaming_writer(run_dir: str, run_id: str, size: int, ready) -> None:
    """Publishes forever (big arrays streamed into the ring), the checksum in the label."""
    ctx = RunContext(run_id, Path(run_dir), owner=False)
    pub = Publisher(ctx, "/stream", M.UInt8MultiArray, publisher_id="writer", depth=2)
    payloads = [np.random.default_rng(i).integers(0, 256, size, dtype=np.uint8) for i in range(3)]
    crcs = [zlib.crc32(p.data) for p in payloads]
    ready.set()
    seq = 0
    while True:
        k = seq % 3
        dim = M.MultiArrayDimension(label=f"{seq}:{crcs[k]}", size=size, stride=size)
        pub.publish(M.UInt8MultiArray(layout=M.MultiArrayLayout(dim=[dim]), data=payloads[k]))
        seq += 1


@needs_c
@pytest.mark.process
@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(size=st.sampled_from([FLOOR + 24, (1 << 20) + 8, 4 << 20]), kill_after=st.floats(0.0, 0.05))
def test_no_torn_message_when_the_writer_is_sigkilled_mid_streaming_copy(ctx, streaming_from_floor, ring_path, size, kill_after):
    sigkill_writer_and_check(ctx, _streaming_writer, size, kill_after)


def _fake_cpu_cache(root: Path, entries: dict[str, tuple[str, str]]) -> str:
    for name, (kind, size) in entries.items():
        (root / name).mkdir(parents=True)
        (root / name / "type").write_text(kind + "\n")
        (root / name / "size").write_text(size + "\n")
    return str(root)


@pytest.mark.unit
def test_the_last_level_cache_is_read_from_sysfs_and_unreadable_ones_are_none(tmp_path):
    layout = {"index0": ("Data", "48K"), "index1": ("Instruction", "32K"), "index2": ("Unified", "2048K"),
              "index3": ("Unified", "266240K")}
    assert codec.last_level_cache_bytes(_fake_cpu_cache(tmp_path / "a", layout)) == 266240 * 1024
    assert codec.last_level_cache_bytes(_fake_cpu_cache(tmp_path / "b", {"index0": ("Data", "32M")})) == 32 << 20
    assert codec.last_level_cache_bytes(_fake_cpu_cache(tmp_path / "c", {"index0": ("Unified", "lots")})) is None
    assert codec.last_level_cache_bytes(str(tmp_path / "missing")) is None
    assert codec.last_level_cache_bytes(_fake_cpu_cache(tmp_path / "d", {"index1": ("Instruction", "32K")})) is None


@pytest.mark.unit
def test_streaming_starts_at_an_eighth_of_the_last_level_cache_or_where_the_environment_says():
    assert codec.stream_min_bytes({}, cache_bytes=32 << 20) == 4 << 20  # a 32 MiB L3: 8 MiB frames stream
    assert codec.stream_min_bytes({}, cache_bytes=260 << 20) == (260 << 20) // 8  # a 260 MiB L3: up to 32.5 MiB plain
    assert codec.stream_min_bytes({}, cache_bytes=512 << 10) == FLOOR  # never below 128 KiB
    assert codec.stream_min_bytes({"EMOS_STREAM_MIN_BYTES": "1048576"}, cache_bytes=260 << 20) == 1 << 20
    assert codec.stream_min_bytes({"EMOS_STREAM_MIN_BYTES": " 0 "}, cache_bytes=260 << 20) == 0  # stream everything
    for bad in ("big", "-5", "1.5e6"):
        with pytest.raises(ValueError, match="EMOS_STREAM_MIN_BYTES: expected a whole number of bytes >= 0"):
            codec.stream_min_bytes({"EMOS_STREAM_MIN_BYTES": bad})
