"""Command and joint messages: TwistArray (Kompass), RGBD (RealSense), joint trajectories and jogs."""
from __future__ import annotations

import numpy as np

from emos.msgs import fields as F
from emos.msgs.registry import Message, message_type
from emos.msgs.sensor import CameraInfo, Image
from emos.msgs.std import Duration, Header


@message_type("kompass_interfaces")
class TwistArray(Message):
    """Candidate velocity commands: ``linear_velocities`` and ``angular_velocities`` are (N, 3)."""

    linear_velocities: np.ndarray = F.array(dtype="float64", ndim=2, shape=(-1, 3))
    angular_velocities: np.ndarray = F.array(dtype="float64", ndim=2, shape=(-1, 3))


@message_type("realsense2_camera_msgs")
class RGBD(Message):
    header: Header = F.message(Header)
    rgb_camera_info: CameraInfo = F.message(CameraInfo)
    depth_camera_info: CameraInfo = F.message(CameraInfo)
    rgb: Image = F.message(Image)
    depth: Image = F.message(Image)


@message_type("trajectory_msgs")
class JointTrajectoryPoint(Message):
    positions: np.ndarray = F.array(dtype="float64", ndim=1)
    velocities: np.ndarray = F.array(dtype="float64", ndim=1)
    accelerations: np.ndarray = F.array(dtype="float64", ndim=1)
    effort: np.ndarray = F.array(dtype="float64", ndim=1)
    time_from_start: Duration = F.message(Duration)


@message_type("trajectory_msgs")
class JointTrajectory(Message):
    header: Header = F.message(Header)
    joint_names: list[str] = F.string_list()
    points: list[JointTrajectoryPoint] = F.message_list(JointTrajectoryPoint)


@message_type("control_msgs")
class JointJog(Message):
    header: Header = F.message(Header)
    joint_names: list[str] = F.string_list()
    displacements: np.ndarray = F.array(dtype="float64", ndim=1)
    velocities: np.ndarray = F.array(dtype="float64", ndim=1)
    duration: float = F.float64()
