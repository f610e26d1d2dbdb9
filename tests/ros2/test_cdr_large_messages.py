"""Large messages through the bridge's CDR codec and Fast DDS profile (no ROS 2 process needed).

Issue 35: a 921,600 B half round trip through the bridge took 12-17x rclpy's. Per-stage stamps
(docs/ros2.md) put almost all of it in Fast DDS repairing lost fragments (~10 ms each, 3 s when a
burst's heartbeat was lost too), and a little in Python copies. These tests count what each fix
changed: bytes allocated per encoded message, bytes taking the one-copy path, and the sizes the
bridge's Fast DDS profile asks for. None of them times anything.
"""
from __future__ import annotations

import tracemalloc
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from emos.interop import ros2_cdr
from emos.interop.ros2 import fastdds as B
from emos.interop.ros2_cdr import Ros2Codec
from emos.msgs import Image, UInt8MultiArray
from emos.msgs.registry import resolve

pytestmark = pytest.mark.unit

IMAGE_BYTES = 921_600
SPLICE_MIN_BYTES = getattr(ros2_cdr, "SPLICE_MIN_BYTES", 65_536)


def _spliced(cdr: Ros2Codec) -> int:
    return int(getattr(cdr, "spliced_bytes", 0))


@pytest.fixture(scope="module")
def cdr() -> Ros2Codec:
    return Ros2Codec("jazzy")


def _image() -> Image:
    rng = np.random.default_rng(7)
    return Image(height=480, width=640, encoding="rgb8", step=1920, data=rng.integers(0, 256, IMAGE_BYTES, dtype=np.uint8))


def _allocated(fn) -> tuple[object, int]:
    """``fn()``'s result and the peak of the memory it allocated (Python and numpy buffers)."""
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        out = fn()
        return out, tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()


def test_a_large_image_is_encoded_with_one_copy_of_its_pixels(cdr):
    """rosbags wrote into a zero-filled bytearray that ``bytes`` copied again: two buffers of
    the image per message (1.84 MB allocated for 921,600 B). One buffer now."""
    msg = _image()
    cdr.serialize(msg)  # plans built, not counted
    before = _spliced(cdr)
    data, peak = _allocated(lambda: cdr.serialize(msg))
    assert isinstance(data, bytes)  # what rclpy's raw publish takes
    assert IMAGE_BYTES <= peak < 1.25 * IMAGE_BYTES, f"{peak} B allocated to encode a {IMAGE_BYTES} B image"
    assert _spliced(cdr) - before == IMAGE_BYTES


def test_decoding_a_large_image_copies_no_pixels(cdr):
    data = cdr.serialize(_image())
    back, peak = _allocated(lambda: cdr.deserialize(Image, data))
    assert np.array_equal(back.data, _image().data)
    assert peak < 0.25 * IMAGE_BYTES, f"{peak} B allocated to decode a {IMAGE_BYTES} B image"


@pytest.mark.parametrize("type_name, dtype", [
    ("std_msgs/msg/UInt8MultiArray", np.uint8), ("std_msgs/msg/Float64MultiArray", np.float64),
    ("std_msgs/msg/Float32MultiArray", np.float32), ("std_msgs/msg/Int32MultiArray", np.int32)])
@pytest.mark.parametrize("dims", [0, 1])  # shifts where the data starts: 8-byte elements need padding or not
def test_the_one_copy_path_writes_what_rosbags_writes(cdr, type_name, dtype, dims):
    cls = resolve(type_name)
    layout_cls = resolve("std_msgs/msg/MultiArrayLayout")
    dim_cls = resolve("std_msgs/msg/MultiArrayDimension")
    count = SPLICE_MIN_BYTES // np.dtype(dtype).itemsize + 3
    layout = layout_cls(dim=[dim_cls(label="x", size=count, stride=count)] * dims, data_offset=0)
    msg = cls(layout=layout, data=np.arange(count).astype(dtype))
    before = _spliced(cdr)
    assert cdr.serialize(msg) == bytes(cdr.serialize_view(msg))
    assert _spliced(cdr) - before == msg.data.nbytes
    back = cdr.deserialize(cls, cdr.serialize(msg))
    assert np.array_equal(back.data, msg.data) and len(back.layout.dim) == dims


def test_small_messages_keep_rosbags_path(cdr):
    msg = UInt8MultiArray(data=np.arange(8, dtype=np.uint8))
    before = _spliced(cdr)
    assert cdr.serialize(msg) == bytes(cdr.serialize_view(msg))
    assert _spliced(cdr) == before


def _profile(shm: bool, loopback_only: bool) -> ET.Element:
    return ET.fromstring(B.fastdds_profile(shm=shm, loopback_only=loopback_only).encode())


def _find(root: ET.Element, path: str) -> list[ET.Element]:
    ns = "{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}"
    return root.findall("./" + "/".join(ns + p for p in path.split("/")))


@pytest.mark.parametrize("shm", [False, True])
@pytest.mark.parametrize("loopback_only", [False, True])
def test_the_bridge_profile_sizes_its_transports_for_large_messages(shm, loopback_only):
    root = _profile(shm, loopback_only)
    kinds = {d.findtext("{*}type"): d for d in _find(root, "transport_descriptors/transport_descriptor")}
    assert set(kinds) == ({"SHM", "UDPv4"} if shm else {"UDPv4"})
    udp = kinds["UDPv4"]
    receive = B.socket_buffer("rmem")
    if receive is not None:
        assert int(udp.findtext("{*}receiveBufferSize") or 0) == receive >= B.MIN_SOCKET_BUFFER
    assert udp.find("{*}sendBufferSize") is None  # the kernel's: see bridge.py
    assert (udp.find("{*}interfaceWhiteList") is not None) == loopback_only
    if shm:
        assert int(kinds["SHM"].findtext("{*}segment_size") or 0) == B.SHM_SEGMENT_BYTES >= 4 * IMAGE_BYTES
    period = _find(root, "data_writer/times/heartbeatPeriod")
    assert len(period) == 1 and int(period[0].findtext("{*}sec") or -1) == 0
    assert int(period[0].findtext("{*}nanosec") or 0) == B.HEARTBEAT_PERIOD_NS <= 100_000_000
    ids = [e.text for e in _find(root, "participant/rtps/userTransports/transport_id")]
    assert ids == (["emos_shm", "emos_udp"] if shm else ["emos_udp"])


@pytest.mark.parametrize("shm", [False, True])
def test_the_bridge_repairs_a_lost_fragment_without_waiting_on_its_own_side(shm):
    """A lost fragment costs the reader's heartbeat-response delay plus the writer's
    NACK-response delay (Fast DDS: 5 ms each; the 9 ms half round trips of 921,600 B over shared
    memory). The bridge's writers and readers answer at once; each is its default profile."""
    root = _profile(shm, loopback_only=True)
    writers = _find(root, "data_writer")
    readers = _find(root, "data_reader")
    assert len(writers) == 1 and writers[0].get("is_default_profile") == "true"
    assert len(readers) == 1 and readers[0].get("is_default_profile") == "true"
    for element, delay in ((writers[0], "nackResponseDelay"), (readers[0], "heartbeatResponseDelay")):
        found = element.findall(f"{{*}}times/{{*}}{delay}")
        assert len(found) == 1, f"{delay} missing from {element.get('profile_name')}"
        assert int(found[0].findtext("{*}sec") or -1) == 0 and int(found[0].findtext("{*}nanosec") or -1) == 0
