"""Message types with ROS field names, numpy arrays for bulk data, and their registry.

``Topic(name="scan", msg_type="LaserScan")`` resolves names through :func:`resolve`; user types
join with the :func:`message_type` decorator and fields from :mod:`emos.msgs.fields`.
"""
from emos.msgs.codec import DecodeError, decode, encode, from_builtin, pack, to_builtin, unpack
from emos.msgs.control import RGBD, JointJog, JointTrajectory, JointTrajectoryPoint, TwistArray
from emos.msgs.fields import FieldTypeError
from emos.msgs.geometry import (
    Point, PointStamped, Pose, Pose2D, PoseStamped, PoseWithCovariance, PoseWithCovarianceStamped,
    Quaternion, TFMessage, Transform, TransformStamped, Twist, TwistStamped, TwistWithCovariance, Vector3, pose_xy_yaw,
)
from emos.msgs.intelligence import (
    Detections, DetectionsMultiSource, PointsOfInterest, StreamingString, Trackings, TrackingsMultiSource, Video,
)
from emos.msgs.nav import MapMetaData, OccupancyGrid, Odometry, Path
from emos.msgs.registry import UnknownMessageType, canonical_name, message_type, registered_types, resolve
from emos.msgs.sensor import (
    Audio, CameraInfo, CompressedImage, Image, JointState, LaserScan, PointCloud2, PointField, RegionOfInterest,
    scan_from_ranges,
)
from emos.msgs.status import ComponentStatus
from emos.msgs.srv import SetBoolRequest, SetBoolResponse, TriggerRequest, TriggerResponse
from emos.msgs.std import (
    Bool, Clock, Duration, LockstepAck, Empty, Float32, Float32MultiArray, Float64, Float64MultiArray, Header, Int32, Int32MultiArray,
    Int64, MultiArrayDimension, MultiArrayLayout, String, Time, UInt8, UInt8MultiArray,
)

# Aliases the ROS stack uses for the same types.
Detection2D = Detections
Detections2D = Detections
Detections2DMultiSource = DetectionsMultiSource

__all__ = [name for name in dir() if not name.startswith("_")]
