"""geometry_msgs."""
from __future__ import annotations

import numpy as np

from emos.geometry import planar_pose, quaternion_of_yaw, yaw_of_quaternion
from emos.msgs import fields as F
from emos.msgs.registry import Message, message_type
from emos.msgs.std import Header


@message_type("geometry_msgs")
class Vector3(Message):
    x: float = F.float64()
    y: float = F.float64()
    z: float = F.float64()


@message_type("geometry_msgs")
class Point(Message):
    x: float = F.float64()
    y: float = F.float64()
    z: float = F.float64()


@message_type("geometry_msgs")
class Quaternion(Message):
    x: float = F.float64()
    y: float = F.float64()
    z: float = F.float64()
    w: float = F.float64(1.0)

    @classmethod
    def from_yaw(cls, yaw: float) -> Quaternion:
        x, y, z, w = quaternion_of_yaw(yaw)
        return cls(x=x, y=y, z=z, w=w)

    def yaw(self) -> float:
        """Heading about z, the angle a planar robot cares about."""
        return yaw_of_quaternion(self.x, self.y, self.z, self.w)


@message_type("geometry_msgs")
class Pose(Message):
    position: Point = F.message(Point)
    orientation: Quaternion = F.message(Quaternion)


@message_type("geometry_msgs")
class Pose2D(Message):
    x: float = F.float64()
    y: float = F.float64()
    theta: float = F.float64()


@message_type("geometry_msgs")
class PoseStamped(Message):
    header: Header = F.message(Header)
    pose: Pose = F.message(Pose)


@message_type("geometry_msgs")
class PoseWithCovariance(Message):
    pose: Pose = F.message(Pose)
    covariance: np.ndarray = F.array(dtype="float64", shape=(36,))


@message_type("geometry_msgs")
class PoseWithCovarianceStamped(Message):
    header: Header = F.message(Header)
    pose: PoseWithCovariance = F.message(PoseWithCovariance)


@message_type("geometry_msgs")
class PoseArray(Message):
    """Poses in one frame (a localizer's particle cloud): ``msg.poses[i].position.x``."""

    header: Header = F.message(Header)
    poses: list[Pose] = F.message_list(Pose)


@message_type("geometry_msgs")
class PointStamped(Message):
    header: Header = F.message(Header)
    point: Point = F.message(Point)


@message_type("geometry_msgs")
class Twist(Message):
    linear: Vector3 = F.message(Vector3)
    angular: Vector3 = F.message(Vector3)


@message_type("geometry_msgs")
class TwistStamped(Message):
    header: Header = F.message(Header)
    twist: Twist = F.message(Twist)


@message_type("geometry_msgs")
class TwistWithCovariance(Message):
    twist: Twist = F.message(Twist)
    covariance: np.ndarray = F.array(dtype="float64", shape=(36,))


@message_type("geometry_msgs")
class Transform(Message):
    translation: Vector3 = F.message(Vector3)
    rotation: Quaternion = F.message(Quaternion)


@message_type("geometry_msgs")
class TransformStamped(Message):
    header: Header = F.message(Header)
    child_frame_id: str = F.string()
    transform: Transform = F.message(Transform)


def pose_xy_yaw(pose: Pose) -> np.ndarray:
    """(x, y, yaw) of a pose, the planar state navigation works with."""
    return np.array(planar_pose(pose))


@message_type("tf2_msgs")
class TFMessage(Message):
    """A batch of transforms (``/tf``, ``/tf_static``): ``msg.transforms[i].transform.translation.x``."""

    transforms: list[TransformStamped] = F.message_list(TransformStamped)
