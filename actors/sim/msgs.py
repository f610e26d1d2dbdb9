"""Convert simulator readings to ``emos.msgs`` messages (ROS field names).

Readings stay plain numpy so the simulator works without the runtime; these converters are
what a sim component uses to publish them on topics.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .sensors.camera import CameraReading
    from .sensors.lidar import ScanReading
    from .sensors.odometry import OdometryReading


def _msgs() -> Any:
    try:
        import emos.msgs as msgs
    except ImportError as exc:  # pragma: no cover - emos.msgs ships with emos
        raise ImportError("converting sim readings to messages needs emos.msgs") from exc
    return msgs


def header(stamp: float, frame_id: str) -> Any:
    m = _msgs()
    ns = int(round(stamp * 1e9))
    return m.Header(stamp=m.Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=frame_id)


def scan_to_msg(scan: ScanReading) -> Any:
    m = _msgs()
    return m.LaserScan(
        header=header(scan.stamp, scan.frame_id), angle_min=scan.angle_min, angle_max=scan.angle_max,
        angle_increment=scan.angle_increment, time_increment=0.0, scan_time=scan.scan_time,
        range_min=scan.range_min, range_max=scan.range_max, ranges=np.asarray(scan.ranges, dtype=np.float32),
        intensities=np.zeros(0, dtype=np.float32),
    )


def camera_to_msgs(reading: CameraReading) -> tuple[Any, Any, Any]:
    """(rgb8 Image, 32FC1 depth Image in metres, CameraInfo) sharing one header."""
    m = _msgs()
    h = header(reading.stamp, reading.frame_id)
    k = reading.k
    rgb = m.Image.from_numpy(reading.rgb, encoding="rgb8", header=h)
    depth = m.Image.from_numpy(np.ascontiguousarray(reading.depth, dtype=np.float32), encoding="32FC1", header=h)
    height, width = reading.depth.shape
    info = m.CameraInfo.from_intrinsics(width, height, k[0, 0], k[1, 1], k[0, 2], k[1, 2], header=h)
    return rgb, depth, info


def cloud_to_msg(reading: CameraReading, stride: int = 1, world_frame: bool = False, world_frame_id: str = "map") -> Any:
    m = _msgs()
    frame = world_frame_id if world_frame else reading.frame_id
    return m.PointCloud2.from_xyz(reading.point_cloud(stride, world_frame), header=header(reading.stamp, frame))


def odometry_to_msg(odom: OdometryReading, pose_variance: float = 0.0, twist_variance: float = 0.0) -> Any:
    m = _msgs()
    pose_cov = np.zeros(36)
    twist_cov = np.zeros(36)
    pose_cov[[0, 7, 35]] = pose_variance
    twist_cov[[0, 7, 35]] = twist_variance
    return m.Odometry(
        header=header(odom.stamp, odom.frame_id),
        child_frame_id=odom.child_frame_id,
        pose=m.PoseWithCovariance(
            pose=m.Pose(position=m.Point(x=odom.x, y=odom.y, z=0.0), orientation=m.Quaternion.from_yaw(odom.yaw)),
            covariance=pose_cov),
        twist=m.TwistWithCovariance(
            twist=m.Twist(linear=m.Vector3(x=odom.vx, y=odom.vy, z=0.0), angular=m.Vector3(x=0.0, y=0.0, z=odom.omega)),
            covariance=twist_cov),
    )
