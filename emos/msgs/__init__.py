"""Message types with ROS field names, numpy arrays for bulk data, and their registry.

``Topic(name="scan", msg_type="LaserScan")`` resolves names through :func:`resolve`; user types
join with the :func:`message_type` decorator and fields from :mod:`emos.msgs.fields`.
"""
from emos.msgs.codec import DecodeError, decode, encode, from_builtin, pack, to_builtin, unpack
from emos.msgs.control import RGBD, JointJog, JointTrajectory, JointTrajectoryPoint, TwistArray
from emos.msgs.fields import FieldTypeError
from emos.msgs.geometry import (
    Point,
    PointStamped,
    Pose,
    Pose2D,
    PoseArray,
    PoseStamped,
    PoseWithCovariance,
    PoseWithCovarianceStamped,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Twist,
    TwistStamped,
    TwistWithCovariance,
    Vector3,
    pose_xy_yaw,
)
from emos.msgs.intelligence import (
    Detections,
    DetectionsMultiSource,
    PointsOfInterest,
    StreamingString,
    Trackings,
    TrackingsMultiSource,
    Video,
)
from emos.msgs.nav import MapMetaData, OccupancyGrid, Odometry, Path
from emos.msgs.registry import UnknownMessageType, canonical_name, message_type, registered_types, resolve
from emos.msgs.sensor import (
    Audio,
    BatteryState,
    CameraInfo,
    CompressedImage,
    Image,
    JointState,
    LaserScan,
    PointCloud2,
    PointField,
    RegionOfInterest,
    scan_from_ranges,
)
from emos.msgs.srv import SetBoolRequest, SetBoolResponse, TriggerRequest, TriggerResponse
from emos.msgs.status import ComponentStatus
from emos.msgs.std import (
    Bool,
    Clock,
    Duration,
    Empty,
    Float32,
    Float32MultiArray,
    Float64,
    Float64MultiArray,
    Header,
    Int32,
    Int32MultiArray,
    Int64,
    LockstepAck,
    MultiArrayDimension,
    MultiArrayLayout,
    String,
    Time,
    UInt8,
    UInt8MultiArray,
)

# Aliases the ROS stack uses for the same types.
Detection2D = Detections
Detections2D = Detections
Detections2DMultiSource = DetectionsMultiSource

# Spelled out (not computed from dir()) so that linters and type checkers see the public names.
__all__ = [
    "Audio", "BatteryState", "Bool", "CameraInfo", "Clock", "ComponentStatus", "CompressedImage", "DecodeError", "Detection2D",
    "Detections", "Detections2D", "Detections2DMultiSource", "DetectionsMultiSource", "Duration", "Empty",
    "FieldTypeError", "Float32", "Float32MultiArray", "Float64", "Float64MultiArray", "Header", "Image", "Int32",
    "Int32MultiArray", "Int64", "JointJog", "JointState", "JointTrajectory", "JointTrajectoryPoint", "LaserScan",
    "LockstepAck", "MapMetaData", "MultiArrayDimension", "MultiArrayLayout", "OccupancyGrid", "Odometry", "Path",
    "Point", "PointCloud2", "PointField", "PointStamped", "PointsOfInterest", "Pose", "Pose2D", "PoseArray", "PoseStamped",
    "PoseWithCovariance", "PoseWithCovarianceStamped", "Quaternion", "RGBD", "RegionOfInterest",
    "SetBoolRequest", "SetBoolResponse", "StreamingString", "String", "TFMessage", "Time", "Trackings",
    "TrackingsMultiSource", "Transform", "TransformStamped", "TriggerRequest", "TriggerResponse", "Twist",
    "TwistArray", "TwistStamped", "TwistWithCovariance", "UInt8", "UInt8MultiArray", "UnknownMessageType",
    "Vector3", "Video", "canonical_name", "decode", "encode", "from_builtin", "message_type", "pack",
    "pose_xy_yaw", "registered_types", "resolve", "scan_from_ranges", "to_builtin", "unpack",
    # the submodules, which `from emos.msgs import *` has always brought along
    "codec", "control", "fields", "geometry", "intelligence", "nav", "registry", "sensor", "srv", "status",
    "std",
]
