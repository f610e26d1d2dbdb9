"""Command and joint messages: TwistArray (Kompass), RGBD (RealSense), joint trajectories and jogs."""
from __future__ import annotations

from emos.msgs import fields as F
from emos.msgs.registry import message_type
from emos.msgs.sensor import CameraInfo, Image
from emos.msgs.std import Duration, Header


@message_type("kompass_interfaces")
class TwistArray:
    """Candidate velocity commands: ``linear_velocities`` and ``angular_velocities`` are (N, 3)."""

    linear_velocities: object = F.array(dtype="float64", ndim=2, shape=(-1, 3))
    angular_velocities: object = F.array(dtype="float64", ndim=2, shape=(-1, 3))


@message_type("realsense2_camera_msgs")
class RGBD:
    header: Header = F.message(Header)
    rgb_camera_info: CameraInfo = F.message(CameraInfo)
    depth_camera_info: CameraInfo = F.message(CameraInfo)
    rgb: Image = F.message(Image)
    depth: Image = F.message(Image)


@message_type("trajectory_msgs")
class JointTrajectoryPoint:
    positions: object = F.array(dtype="float64", ndim=1)
    velocities: object = F.array(dtype="float64", ndim=1)
    accelerations: object = F.array(dtype="float64", ndim=1)
    effort: object = F.array(dtype="float64", ndim=1)
    time_from_start: Duration = F.message(Duration)


@message_type("trajectory_msgs")
class JointTrajectory:
    header: Header = F.message(Header)
    joint_names: list = F.string_list()
    points: list = F.message_list(JointTrajectoryPoint)


@message_type("control_msgs")
class JointJog:
    header: Header = F.message(Header)
    joint_names: list = F.string_list()
    displacements: object = F.array(dtype="float64", ndim=1)
    velocities: object = F.array(dtype="float64", ndim=1)
    duration: float = F.float64()
