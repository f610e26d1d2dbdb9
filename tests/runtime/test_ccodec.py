"""The codec's C fast path (emos/msgs/_ccodec.c) against the Python codec it stands in for.

The C code must return exactly what the Python codec returns, or give up so that the Python
codec runs: on every registered message type with default and random contents, on frames in
every kind of buffer, and on thousands of mutated and random frames (bytes another process may
have put on a ring or a key). It must never succeed where the Python codec raises.
"""
from __future__ import annotations

import os
import random
import subprocess
import sys

import attrs
import numpy as np
import pytest

from emos.msgs import codec
from emos.msgs import fields as F
from emos.msgs.registry import registered_types
from emos.transport import netframe
from emos.transport.netframe import FrameWriter
from tests.c_build import can_build_c_extensions

pytestmark = pytest.mark.process

C = codec.C_CODEC
needs_c = pytest.mark.skipif(C is None, reason="the C codec is not built (no compiler at install, or EMOS_CODEC=python)")
TYPES = sorted(set(registered_types().values()), key=lambda cls: cls.__name__)


def test_the_c_codec_is_built_wherever_a_compiler_is():
    """An install with a C compiler and Python's headers builds it: a silent build failure would
    leave every user on the slow path, so it is a failure here."""
    if not can_build_c_extensions() or os.environ.get("EMOS_CODEC") == "python":
        pytest.skip("no C compiler or Python headers here, or the C codec turned off")
    assert C is not None, "emos.msgs._ccodec is missing: run `pip install -e .` again and read the compiler's output"
    assert codec.encode is C.encode and codec.decode is C.decode


def test_emos_codec_python_turns_the_fast_path_off():
    out = subprocess.run([sys.executable, "-c", "from emos.msgs import codec; print(codec.C_CODEC, codec.encode is codec.encode_python)"],
                         env={**os.environ, "EMOS_CODEC": "python"}, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["None", "True"]


# ----------------------------------------------------------------------------- messages to try
def _random_value(field: attrs.Attribute, current, rng: random.Random, depth: int):
    kind = field.metadata.get("kind", F.PRIMITIVE)
    cls = field.metadata.get("cls")
    if kind == F.MESSAGE:
        return _random_message(cls(), rng, depth + 1)
    if kind == F.OPTIONAL_MESSAGE:
        return None if rng.random() < 0.3 else _random_message(cls(), rng, depth + 1)
    if kind == F.MESSAGE_LIST:
        return [_random_message(cls(), rng, depth + 1) for _ in range(rng.randrange(0 if depth > 2 else 4))]
    if kind == F.STR_LIST:
        return [_random_str(rng) for _ in range(rng.randrange(4))]
    if kind == F.ARRAY:
        dtype = current.dtype
        shape = current.shape if current.size else (rng.randrange(1, 6),) * max(current.ndim, 1)
        raw = np.frombuffer(rng.randbytes(int(np.prod(shape)) * dtype.itemsize), dtype=np.uint8)
        arr = raw.view(dtype).reshape(shape)
        return np.nan_to_num(arr) if dtype.kind == "f" else arr
    if isinstance(current, bool):
        return rng.random() < 0.5
    if isinstance(current, int):
        return rng.choice([0, 1, 127, 128, 255, 256, 32767, rng.randrange(0, 2**31)])
    if isinstance(current, float):
        return rng.choice([0.0, -0.0, 1.5, -1e300, float("inf"), rng.uniform(-1e6, 1e6)])
    if isinstance(current, str):
        return _random_str(rng)
    return current


def _random_str(rng: random.Random) -> str:
    return "".join(rng.choice("ab/_-é✓ 🤖") for _ in range(rng.choice([0, 3, 31, 32, 255, 256])))


def _random_message(msg, rng: random.Random, depth: int = 0):
    for field in attrs.fields(type(msg)):
        try:
            setattr(msg, field.name, _random_value(field, getattr(msg, field.name), rng, depth))
        except (TypeError, ValueError):
            pass  # a converter's rule (a fixed shape, a range) the generator does not know: keep the default
    return msg


def _samples():
    rng = random.Random(7)
    for cls in TYPES:
        yield cls()
        for _ in range(3):
            yield _random_message(cls(), rng)


SAMPLES = list(_samples())


def _same(a, b, path="msg"):
    """a and b are the same decoded value: type, every field, and for arrays dtype, shape,
    bytes, writability, alignment and base (copy or view of the same object)."""
    assert type(a) is type(b), f"{path}: {type(a).__name__} != {type(b).__name__}"
    if isinstance(a, np.ndarray):
        assert (a.dtype, a.shape, a.tobytes()) == (b.dtype, b.shape, b.tobytes()), path
        assert (a.flags.writeable, a.flags.aligned, a.flags.owndata, a.flags.c_contiguous) == (
            b.flags.writeable, b.flags.aligned, b.flags.owndata, b.flags.c_contiguous), path
        assert a.base is b.base or (a.base is not None and b.base is not None and type(a.base) is type(b.base) and a.flags.owndata == b.flags.owndata), path
    elif attrs.has(type(a)):
        for field in attrs.fields(type(a)):
            _same(getattr(a, field.name), getattr(b, field.name), f"{path}.{field.name}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and a != a:
        assert b != b, path
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"


# ------------------------------------------------------------------------------------- encoding
@needs_c
@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: type(m).__name__)
def test_c_encodes_every_message_type_byte_for_byte_as_python(msg):
    fast = C.try_encode(msg)
    assert fast is not NotImplemented, f"{type(msg).__name__}: the fast path gave up on a plain message"
    slow = codec.encode_python(msg)
    assert fast.meta == slow.meta
    assert fast.array_bytes == slow.array_bytes
    assert len(fast.arrays) == len(slow.arrays) and all(a is b for a, b in zip(fast.arrays, slow.arrays))
    assert fast.to_bytes() == slow.to_bytes()


@needs_c
def test_values_the_fast_path_does_not_write_take_the_python_path_with_the_same_result():
    from emos.msgs import Float64MultiArray, Header, Time

    strided = Float64MultiArray(data=np.arange(10.0)[::2])  # not contiguous: Python copies it
    subclass = type("MyHeader", (Header,), {})
    cases = [strided, Header(stamp=Time(sec=3), frame_id="x")]
    for msg in cases:
        assert codec.encode(msg).to_bytes() == codec.encode_python(msg).to_bytes()
    if not strided.data.flags.c_contiguous:  # the converter kept the strided view
        assert C.try_encode(strided) is NotImplemented
    big = Time(sec=2**31 - 1, nanosec=2**32 - 1)  # the largest values, at the msgpack width boundaries
    assert C.try_encode(big).meta == codec.encode_python(big).meta
    try:
        odd = subclass(frame_id="y")
    except Exception:  # noqa: BLE001 - attrs may refuse the ad hoc subclass; nothing to compare then
        return
    assert codec.encode(odd).to_bytes() == codec.encode_python(odd).to_bytes()


@needs_c
def test_an_object_array_is_refused_with_the_python_codecs_error():
    from emos.msgs import Float64MultiArray

    msg = Float64MultiArray()
    object.__setattr__(msg, "data", np.array([object()], dtype=object))  # past the converter
    with pytest.raises(TypeError, match="only plain numeric dtypes"):
        codec.encode(msg)


# ------------------------------------------------------------------------------------- decoding
def _buffers(frame: bytes):
    yield frame
    yield bytearray(frame)
    yield memoryview(frame)
    yield memoryview(bytearray(frame)).toreadonly()
    yield memoryview(b"\0" * 8 + frame)[8:]


@needs_c
@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: type(m).__name__)
def test_c_decodes_every_message_type_as_python(msg):
    cls, frame = type(msg), codec.encode_python(msg).to_bytes()
    for buf in _buffers(frame):
        for copy in (False, True):
            fast = C.try_decode(cls, buf, copy=copy)
            assert fast is not NotImplemented, f"{cls.__name__} in a {type(buf).__name__}: the fast path gave up on a valid frame"
            _same(fast, codec.decode_python(cls, buf, copy=copy))
    # A message in two parts (the network's large messages): header, then the array region apart.
    enc = codec.encode_python(msg)
    head = b"".join(enc.head_chunks())
    region = bytearray(enc.array_bytes)
    enc.write_arrays_into(memoryview(region))
    _same(C.try_decode(cls, head, arrays=bytes(region)), codec.decode_python(cls, head, arrays=bytes(region)))


def _mutations(frame: bytes, rng: random.Random, count: int):
    for _ in range(count):
        data = bytearray(frame)
        how = rng.randrange(6)
        if how == 0 and data:  # flip bytes
            for _ in range(rng.randrange(1, 4)):
                data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        elif how == 1 and data:  # set a byte to a msgpack marker
            data[rng.randrange(min(len(data), 64))] = rng.choice([0x90, 0x9f, 0xdc, 0xdd, 0xc0, 0xc1, 0xc4, 0xc7, 0xc9, 0xca, 0xcb, 0xcf, 0xd3,
                                                                 0xd4, 0xd7, 0xd8, 0xd9, 0xdb, 0xde, 0x80, 0xff, 0xa5])
        elif how == 2:  # truncate
            del data[rng.randrange(len(data) + 1):]
        elif how == 3:  # a lie in the metadata length
            data[0:4] = rng.randrange(2**32).to_bytes(4, "little") if rng.random() < 0.5 else (int.from_bytes(data[0:4], "little") + rng.choice([-3, -1, 1, 8])).to_bytes(4, "little", signed=True)
        elif how == 4:  # bytes appended
            data += rng.randbytes(rng.randrange(1, 16))
        else:  # random bytes
            data = bytearray(rng.randbytes(rng.randrange(40)))
        yield bytes(data)


@needs_c
def test_mutated_and_random_frames_decode_as_python_or_take_the_python_path():
    """Frames another process may have written: the fast path never reads outside them, never
    succeeds where the Python codec raises, and never returns anything else than it does."""
    rng = random.Random(11)
    tried = agreed = 0
    for msg in SAMPLES[::2]:
        cls, frame = type(msg), codec.encode_python(msg).to_bytes()
        for bad in _mutations(frame, rng, 60):
            tried += 1
            try:
                expected = codec.decode_python(cls, bad)
            except codec.DecodeError:
                expected = None
            fast = C.try_decode(cls, bad)
            if expected is None:
                assert fast is NotImplemented, f"{cls.__name__}: the fast path decoded a frame the Python codec refuses: {bad!r}"
                with pytest.raises(codec.DecodeError):
                    codec.decode(cls, bad)  # the error a user sees is the Python codec's
            elif fast is not NotImplemented:
                _same(fast, expected)
                agreed += 1
    assert tried > 5000 and agreed > 100  # the mutations do reach frames that still decode


# ------------------------------------------------------------------------------- network frames
@needs_c
@pytest.mark.parametrize("msg", SAMPLES[::3], ids=lambda m: type(m).__name__)
def test_a_whole_network_frame_is_written_and_read_as_netframes_python(msg):
    cls = type(msg)
    writer = FrameWriter(cls._emos_fingerprint, "lidar_driver")
    slow = codec.encode_python(msg)
    expected = bytes(writer.frame(slow, 123456789))
    out = C.frame_message(msg, writer.header, 123456789, FrameWriter.SMALL)
    if slow.array_bytes + len(slow.meta) < FrameWriter.SMALL:
        assert out == expected
    else:  # a large one comes back encoded, for FrameWriter.split
        assert isinstance(out, codec.Encoded) and out.meta == slow.meta
    fp = cls._emos_fingerprint.encode()
    netframe._checked.clear()
    assert C.try_read_message(expected, fp, cls) is NotImplemented  # a new publisher: netframe checks its names first
    stamp, pub, first = netframe.read_message(expected, fp, cls)
    fast = C.try_read_message(expected, fp, cls)
    assert fast is not NotImplemented and fast[:2] == (stamp, pub) == (123456789, "lidar_driver")
    _same(fast[2], first)
    _same(fast[2], netframe.read_message_python(expected, fp, cls)[2])
    for value in attrs.astuple(netframe.read_message(bytearray(expected), fp, cls)[2], recurse=False):
        assert not isinstance(value, np.ndarray) or not value.flags.writeable  # received arrays are read-only


@needs_c
def test_bad_network_frames_raise_netframes_errors():
    from emos.msgs import Header, String

    writer = FrameWriter(String._emos_fingerprint, "talker")
    frame = C.frame_message(String(data="hi"), writer.header, 5, FrameWriter.SMALL)
    fp = String._emos_fingerprint.encode()
    assert netframe.read_message(frame, fp, String)[2].data == "hi"
    with pytest.raises(netframe.BadFrame, match="fingerprint"):
        netframe.read_message(frame, Header._emos_fingerprint.encode(), Header)
    with pytest.raises(netframe.BadFrame, match="not an EMOS frame"):
        netframe.read_message(b"XXXX" + frame[4:], fp, String)
    with pytest.raises(codec.DecodeError):
        body = writer.start + 4  # the message's metadata, after its length
        netframe.read_message(frame[:body] + b"\xc1" * (len(frame) - body), fp, String)  # a well-framed body that lies
    rng = random.Random(3)
    for bad in _mutations(frame, rng, 3000):
        try:
            expected = netframe.read_message_python(bad, fp, String)
        except (netframe.BadFrame, codec.DecodeError):
            expected = None
        fast = C.try_read_message(bad, fp, String)
        if expected is None:
            assert fast is NotImplemented, bad
        elif fast is not NotImplemented:
            assert fast[:2] == expected[:2]
            _same(fast[2], expected[2])


@needs_c
def test_a_frame_stamped_by_the_c_code_carries_the_wall_clock():
    import time

    from emos.msgs import String

    writer = FrameWriter(String._emos_fingerprint, "talker")
    before = time.time_ns()
    frame = C.frame_message(String(data="now"), writer.header, None, FrameWriter.SMALL)
    after = time.time_ns()
    stamp, pub, msg = netframe.read_message(frame, String._emos_fingerprint.encode(), String)
    assert before <= stamp <= after and (pub, msg.data) == ("talker", "now")


@needs_c
def test_the_last_publisher_shortcut_never_admits_a_frame_netframe_would_refuse():
    """read_message remembers the last publisher whose names it accepted, for that subscriber's
    fingerprint: another publisher, another type, or the same names for another fingerprint
    still go through netframe's checks."""
    from emos.msgs import Header, String

    fp_string, fp_header = String._emos_fingerprint.encode(), Header._emos_fingerprint.encode()
    a = C.frame_message(String(data="a"), FrameWriter(String._emos_fingerprint, "alice").header, 1, FrameWriter.SMALL)
    b = C.frame_message(String(data="b"), FrameWriter(String._emos_fingerprint, "bob").header, 2, FrameWriter.SMALL)
    netframe._checked.clear()
    assert netframe.read_message(a, fp_string, String)[1:2] == ("alice",)
    assert C.try_read_message(a, fp_string, String)[1] == "alice"  # the shortcut
    assert C.try_read_message(b, fp_string, String) is NotImplemented  # bob's names: not checked yet
    assert netframe.read_message(b, fp_string, String)[1] == "bob"
    assert C.try_read_message(a, fp_string, String)[1] == "alice"  # back to the first: through the dict
    with pytest.raises(netframe.BadFrame, match="fingerprint"):
        netframe.read_message(a, fp_header, Header)  # alice's names, a subscriber of another type
    equal_not_same = bytes(bytearray(fp_string))  # another object with the same fingerprint
    assert C.try_read_message(a, equal_not_same, String)[1] == "alice"
