"""Message types: construction checks, string resolution, registry, codec round trips."""
import numpy as np
import pytest

from emos import msgs as M
from emos.msgs import codec
from emos.msgs import fields as F
from emos.msgs.registry import UnknownMessageType, message_type, registered_types, resolve

pytestmark = pytest.mark.unit

SPEC_TYPES = [
    "String", "Bool", "Float32", "Float32MultiArray", "Float64", "Float64MultiArray", "Point", "PointStamped", "Pose",
    "PoseStamped", "Twist", "TwistStamped", "Image", "CompressedImage", "Audio", "LaserScan", "PointCloud2", "CameraInfo",
    "JointState", "Odometry", "Path", "MapMetaData", "OccupancyGrid", "StreamingString", "Video", "Detections",
    "DetectionsMultiSource", "PointsOfInterest", "Trackings", "TrackingsMultiSource", "TwistArray", "RGBD",
    "JointTrajectoryPoint", "JointTrajectory", "JointJog", "ComponentStatus",
]


@pytest.mark.parametrize("name", SPEC_TYPES)
def test_every_supported_type_resolves_and_round_trips_its_default(name):
    cls = resolve(name)
    msg = cls()
    back = codec.decode(cls, codec.pack(msg))
    assert codec.to_builtin(back) == codec.to_builtin(msg)


def test_ros_style_names_resolve_to_the_same_class():
    assert resolve("sensor_msgs/msg/LaserScan") is M.LaserScan
    assert resolve("sensor_msgs/LaserScan") is M.LaserScan
    assert resolve("sensor_msgs.msg.LaserScan") is M.LaserScan
    assert resolve(M.LaserScan) is M.LaserScan


def test_unknown_type_lists_close_matches():
    with pytest.raises(UnknownMessageType, match="did you mean 'LaserScan'"):
        resolve("LazerScan")
    with pytest.raises(UnknownMessageType, match="unknown message type 'Qwertyuiop'$"):
        resolve("Qwertyuiop")


def test_wrong_field_types_fail_on_construction_and_assignment():
    with pytest.raises(F.FieldTypeError, match=r"Float32\.data expects a float, got str"):
        M.Float32(data="1.5")
    msg = M.Float32(data=1)
    assert msg.data == 1.0 and isinstance(msg.data, float)
    with pytest.raises(F.FieldTypeError, match=r"Float32\.data"):
        msg.data = None
    with pytest.raises(F.FieldTypeError, match=r"Header\.frame_id expects a str"):
        M.Header(frame_id=3)
    with pytest.raises(F.FieldTypeError, match=r"CameraInfo\.k expects an array of float64 with shape \(9,\)"):
        M.CameraInfo(k=[1, 2, 3])
    with pytest.raises(F.FieldTypeError, match="UInt8.data"):
        M.UInt8(data=300)
    with pytest.raises(ValueError, match="as many scores and boxes as labels"):
        M.Detections(labels=["a", "b"], scores=[0.5], boxes=[[0, 0, 1, 1]])


def test_nested_messages_and_ros_field_paths():
    odom = M.Odometry()
    odom.twist.twist.linear.x = 0.7
    odom.pose.pose.orientation = M.Quaternion.from_yaw(1.0)
    back = codec.decode(M.Odometry, codec.pack(odom))
    assert back.twist.twist.linear.x == 0.7
    assert abs(back.pose.pose.orientation.yaw() - 1.0) < 1e-12


def test_image_numpy_round_trip_keeps_bytes_dtype_and_shape():
    rgb = np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    img = M.Image.from_numpy(rgb, "rgb8")
    assert (img.height, img.width, img.step) == (48, 64, 192)
    back = codec.decode(M.Image, codec.pack(img))
    np.testing.assert_array_equal(back.to_numpy(), rgb)
    depth = np.random.default_rng(1).random((10, 12), dtype=np.float32)
    np.testing.assert_array_equal(codec.decode(M.Image, codec.pack(M.Image.from_numpy(depth, "32FC1"))).to_numpy(), depth)
    with pytest.raises(TypeError, match="needs dtype uint8"):
        M.Image.from_numpy(depth, "rgb8")


def test_arrays_keep_dtype_and_non_contiguous_input_is_handled():
    ranges = np.arange(20, dtype=np.float32)[::2]  # a strided view
    scan = M.LaserScan(ranges=ranges)
    back = codec.decode(M.LaserScan, codec.pack(scan))
    assert back.ranges.dtype == np.float32
    np.testing.assert_array_equal(back.ranges, ranges)


def test_point_cloud_xyz_round_trip():
    pts = np.random.default_rng(2).normal(size=(100, 3)).astype(np.float32)
    cloud = codec.decode(M.PointCloud2, codec.pack(M.PointCloud2.from_xyz(pts)))
    np.testing.assert_array_equal(cloud.xyz(), pts)


def test_users_register_their_own_types():
    @message_type("my_robot_msgs")
    class MotorState:
        voltage: float = F.float64()
        cells: object = F.array(dtype="float32", ndim=1)
        location: M.Point = F.message(M.Point)

    assert resolve("MotorState") is MotorState
    assert resolve("my_robot_msgs/msg/MotorState") is MotorState
    msg = MotorState(voltage=24.1, cells=[4.0, 4.1], location=M.Point(x=1.0))
    back = codec.decode(MotorState, codec.pack(msg))
    assert back.voltage == 24.1 and back.location.x == 1.0
    np.testing.assert_allclose(back.cells, [4.0, 4.1])
    assert "my_robot_msgs/msg/MotorState" in registered_types()


def test_garbage_frames_raise_decode_errors_not_crashes():
    good = codec.pack(M.LaserScan(ranges=np.ones(10, np.float32)))
    for bad in (b"", b"\x05\x00\x00\x00abc", good[:20], b"\xff" * 64):
        with pytest.raises(codec.DecodeError):
            codec.decode(M.LaserScan, bad)
    with pytest.raises(codec.DecodeError, match="expects"):
        codec.decode(M.Odometry, codec.pack(M.String(data="x")))


def test_builtin_round_trip_validates_fields():
    data = codec.to_builtin(M.Twist(linear=M.Vector3(x=1.0)))
    assert codec.from_builtin(M.Twist, data).linear.x == 1.0
    with pytest.raises(TypeError, match="has no field 'speed'"):
        codec.from_builtin(M.Twist, {"speed": 1})


def test_object_arrays_never_travel():
    with pytest.raises(F.FieldTypeError):
        M.Float64MultiArray(data=np.array([object()], dtype=object))


@pytest.mark.parametrize("dtype", [">f4", "<f8", "float16", "complex64", "bool", "int16", ">i8"])
def test_any_plain_dtype_travels_with_its_byte_order(dtype):
    data = (np.arange(12) % 5).astype(dtype).reshape(3, 4)
    from emos.msgs import fields as F
    from emos.msgs.registry import message_type

    @message_type("test_msgs", name=f"Any_{dtype.replace('>', 'be').replace('<', 'le')}")
    class AnyArray:
        data: object = F.array()

    back = codec.decode(AnyArray, codec.pack(AnyArray(data=data)))
    assert back.data.dtype == np.dtype(dtype) and back.data.shape == (3, 4)
    np.testing.assert_array_equal(back.data, data)


def test_short_lived_dtypes_of_one_shape_never_share_a_cached_header():
    # The encoder caches array headers by the dtype object's identity (hashing a dtype is slow);
    # dtypes built and dropped one after another may get the same id, and each must still
    # travel as itself.
    from emos.msgs import fields as F
    from emos.msgs.registry import message_type

    @message_type("test_msgs", name="AnyArrayShortLived")
    class AnyArray:
        data: object = F.array()

    for i in range(200):
        dtype = np.dtype(["<f4", ">f4", "<i4", ">i4", "<u4"][i % 5])  # fresh objects for non-native orders
        data = (np.arange(6) + i).astype(dtype)
        back = codec.decode(AnyArray, codec.pack(AnyArray(data=data)))
        assert back.data.dtype == dtype, (i, back.data.dtype, dtype)
        np.testing.assert_array_equal(back.data, data)
        del dtype, data, back


def test_array_header_caches_stay_bounded_and_correct_when_shapes_keep_changing():
    for n in range(codec._HEADER_CACHE_SIZE + 50):
        data = np.full(n % 97 + 1, n % 251, dtype=np.uint8)
        back = codec.decode(M.UInt8MultiArray, codec.pack(M.UInt8MultiArray(data=data)))
        np.testing.assert_array_equal(back.data, data)
    scans = [M.LaserScan(ranges=np.arange(k, dtype=np.float32)) for k in range(1, 30)]
    for scan in scans:
        np.testing.assert_array_equal(codec.decode(M.LaserScan, codec.pack(scan)).ranges, scan.ranges)
    assert len(codec._HEADERS_IN) <= codec._HEADER_CACHE_SIZE
    assert len(codec._HEADERS_OUT) <= codec._HEADER_CACHE_SIZE


def test_a_forged_array_header_is_a_decode_error():
    import msgpack

    forged = msgpack.packb([[], msgpack.ExtType(1, msgpack.packb(("|u1", [10**12], 0)))])
    frame = len(forged).to_bytes(4, "little") + forged
    with pytest.raises(codec.DecodeError, match="past the end"):
        codec.decode(M.UInt8MultiArray, frame)
