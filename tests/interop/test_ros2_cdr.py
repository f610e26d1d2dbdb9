"""ROS 2 CDR conversion of the message types we share with ROS 2.

Round trips cover every shared type with non-default values; a few types are also checked
against bytes built here by hand from the CDR rules (XCDR1, little endian: encapsulation header
00 01 00 00, then every primitive aligned to its size counted from the end of that header,
strings as u32 length including the NUL, sequences as u32 count then elements), so the codec is
not only compared with the library it uses.
"""
from __future__ import annotations

import struct

import attrs
import numpy as np
import pytest

pytest.importorskip("rosbags")

from emos.interop.ros2_cdr import CdrError, NotShared, Ros2Codec, codec_for
from emos.msgs import (
    ComponentStatus,
    Detections,
    Empty,
    Header,
    Image,
    LaserScan,
    MapMetaData,
    OccupancyGrid,
    Pose,
    String,
    Time,
    Vector3,
    codec,
    registered_types,
)
from emos.msgs import fields as F

pytestmark = pytest.mark.unit

CODEC = codec_for("humble")

# Which of our packages must be shared (the brief: the standard ROS 2 message packages).
SHARED_PACKAGES = ("std_msgs", "geometry_msgs", "sensor_msgs", "nav_msgs", "builtin_interfaces", "trajectory_msgs",
                   "tf2_msgs", "rosgraph_msgs")

_VALUES = {
    "bool": True, "byte": 0xAB, "char": 7, "int8": -100, "uint8": 200, "int16": -30000, "uint16": 60000,
    "int32": -123456, "uint32": 4_000_000_000, "int64": -(2**40) - 3, "uint64": 2**50 + 1,
    "float32": 1.5, "float64": 0.1, "string": "emos ü",
}


def sample(cls: type, store, depth: int = 0):
    """An instance of ``cls`` with a non-default value in every field, chosen from the ROS 2 field type."""
    ros = dict(store.fielddefs[registered_types_inverse(cls)][1])
    kwargs = {}
    for f in attrs.fields(cls):
        node, spec = ros[f.name]
        kind = f.metadata.get("kind")
        if kind == F.MESSAGE:
            kwargs[f.name] = sample(f.metadata["cls"](), store, depth + 1)
        elif kind == F.MESSAGE_LIST:
            kwargs[f.name] = [sample(f.metadata["cls"](), store, depth + 1) for _ in range(2)]
        elif kind == F.STR_LIST:
            kwargs[f.name] = ["a", "bé", ""]
        elif kind == F.ARRAY:
            base = spec[0][1][0]
            n = spec[1] if node == 3 else 5
            dtype = np.dtype({"byte": "uint8", "char": "uint8"}.get(base, base))
            kwargs[f.name] = (np.arange(n) % 100 + 1).astype(dtype) * (-1 if dtype.kind in "if" and n % 2 else 1)
        else:
            kwargs[f.name] = _VALUES[spec[0]]
    return cls(**kwargs)


def registered_types_inverse(cls: type) -> str:
    return {c: n for n, c in registered_types().items()}[cls]


def builtin(msg):
    return codec.to_builtin(msg)


def test_every_standard_type_is_shared_and_nothing_else():
    shared = CODEC.shared_types()
    for name in registered_types():
        expected = name.split("/")[0] in SHARED_PACKAGES
        assert (name in shared) == expected, name
    assert len(shared) >= 40


@pytest.mark.parametrize("name", sorted(codec_for("humble").shared_types()))
def test_round_trip_through_cdr(name):
    cls = CODEC.shared_types()[name]
    msg = sample(cls, CODEC.store)
    data = CODEC.serialize(msg)
    assert data[:4] == b"\x00\x01\x00\x00"
    back = CODEC.deserialize(cls, data)
    assert type(back) is cls
    assert builtin(back) == builtin(msg)


def test_humble_and_jazzy_definitions_give_the_same_bytes():
    jazzy = Ros2Codec("jazzy")
    for name, cls in CODEC.shared_types().items():
        msg = sample(cls, CODEC.store)
        assert jazzy.serialize(msg) == CODEC.serialize(msg), name


def _cdr_string(s: str, pos: int) -> tuple[bytes, int]:
    raw = s.encode() + b"\x00"
    return struct.pack("<I", len(raw)) + raw, pos + 4 + len(raw)


def _pad(buf: bytearray, align: int) -> None:
    while len(buf) % align:
        buf.append(0)


def test_string_matches_hand_built_bytes():
    assert CODEC.serialize(String(data="hi")) == bytes.fromhex("00010000" "03000000" "686900")


def test_vector3_matches_hand_built_bytes():
    assert CODEC.serialize(Vector3(x=1.0, y=-2.0, z=0.5)) == b"\x00\x01\x00\x00" + struct.pack("<3d", 1.0, -2.0, 0.5)


def test_empty_has_rosidl_placeholder_byte():
    assert CODEC.serialize(Empty()) == b"\x00\x01\x00\x00\x00"


def test_laser_scan_matches_hand_built_bytes():
    scan = LaserScan(header=Header(stamp=Time(sec=1, nanosec=2), frame_id="laser"), angle_min=-1.5, angle_max=1.5,
                     angle_increment=0.25, time_increment=0.0, scan_time=0.05, range_min=0.1, range_max=10.0,
                     ranges=np.array([1.0, 2.5], np.float32))
    body = bytearray(struct.pack("<iI", 1, 2))
    s, _ = _cdr_string("laser", 8)
    body += s                                   # 8..18
    _pad(body, 4)                               # float32s align to 4: 18 -> 20
    body += struct.pack("<7f", -1.5, 1.5, 0.25, 0.0, 0.05, 0.1, 10.0)
    body += struct.pack("<I2f", 2, 1.0, 2.5)    # ranges: count, values
    body += struct.pack("<I", 0)                # intensities: empty
    assert CODEC.serialize(scan) == b"\x00\x01\x00\x00" + bytes(body)


def test_image_matches_hand_built_bytes():
    img = Image.from_numpy(np.array([[7, 9]], np.uint8), "mono8", header=Header(frame_id="cam"))
    body = bytearray(struct.pack("<iI", 0, 0))
    body += _cdr_string("cam", 8)[0]            # 8..16
    body += struct.pack("<II", 1, 2)            # height, width
    body += _cdr_string("mono8", 24)[0]         # 24..34
    body += b"\x00"                             # is_bigendian (uint8) at 34
    _pad(body, 4)                               # step (uint32) aligns: 35 -> 36
    body += struct.pack("<I", 2)
    body += struct.pack("<I", 2) + bytes([7, 9])
    assert CODEC.serialize(img) == b"\x00\x01\x00\x00" + bytes(body)


def test_occupancy_grid_matches_hand_built_bytes():
    grid = OccupancyGrid(
        header=Header(frame_id="map"),
        info=MapMetaData(resolution=0.5, width=3, height=1, origin=Pose()),
        data=np.array([-1, 0, 100], np.int8),
    )
    grid.info.origin.position.x = 2.0
    body = bytearray(struct.pack("<iI", 0, 0))
    body += _cdr_string("map", 8)[0]            # 8..16
    body += struct.pack("<iI", 0, 0)            # map_load_time
    body += struct.pack("<f", 0.5)              # resolution at 24
    body += struct.pack("<II", 3, 1)            # width, height: 28..36
    _pad(body, 8)                               # float64 aligns to 8: 36 -> 40
    body += struct.pack("<3d", 2.0, 0.0, 0.0) + struct.pack("<4d", 0.0, 0.0, 0.0, 1.0)
    body += struct.pack("<I", 3) + struct.pack("<3b", -1, 0, 100)
    data = CODEC.serialize(grid)
    assert data == b"\x00\x01\x00\x00" + bytes(body)
    assert builtin(CODEC.deserialize(OccupancyGrid, data)) == builtin(grid)


def test_full_definition_is_the_concatenated_ros2msg_text():
    text = CODEC.message_definition(LaserScan)
    assert text.startswith("std_msgs/Header header\nfloat32 angle_min\n")
    assert "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id" in text
    assert "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec" in text


def test_types_without_ros_counterpart_are_refused_with_the_reason():
    with pytest.raises(NotShared, match="sugar/msg/ComponentStatus is not a ROS 2 humble type"):
        CODEC.serialize(ComponentStatus())
    assert not CODEC.is_shared(Detections)
    with pytest.raises(NotShared):
        CODEC.class_for("visualization_msgs/msg/MarkerArray")


def test_bad_bytes_and_bad_values_are_clear_errors():
    with pytest.raises(CdrError, match="not a CDR payload"):
        CODEC.deserialize(LaserScan, b"\x01\x02")
    good = CODEC.serialize(LaserScan(ranges=np.ones(100, np.float32)))
    with pytest.raises(CdrError, match="sensor_msgs/msg/LaserScan"):
        CODEC.deserialize(LaserScan, good[:60])
    from emos.msgs import CameraInfo

    cam = CameraInfo()
    object.__setattr__(cam, "k", np.zeros(4))  # bypass our own validation: the codec must still refuse
    with pytest.raises(CdrError, match="CameraInfo.k must hold 9 values"):
        CODEC.serialize(cam)


def test_unknown_distribution_names_the_choices():
    with pytest.raises(ValueError, match="humble"):
        Ros2Codec("rolling-2099")
