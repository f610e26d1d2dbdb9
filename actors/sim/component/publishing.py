"""Simulator readings to messages: the transform tree, camera frames (raw, JPEG, RGBD), the map."""
from __future__ import annotations

import io
import math
from typing import Any

import numpy as np

from emos import msgs as M
from emos.geometry import quaternion_of_yaw

from ..msgs import camera_to_msgs, header
from ..sensors.camera import Camera, CameraReading
from ..sensors.lidar import Lidar
from ..sensors.odometry import OdometryReading


def quaternion_from_matrix(r: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a proper rotation matrix (Shepperd's method, stable for every angle)."""
    t = float(np.trace(r))
    if t > 0:
        s = math.sqrt(t + 1.0) * 2
        return ((r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s)
    i = int(np.argmax(np.diag(r)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k]) * 2
    q = [0.0, 0.0, 0.0, (r[k, j] - r[j, k]) / s]
    q[i] = 0.25 * s
    q[j] = (r[j, i] + r[i, j]) / s
    q[k] = (r[k, i] + r[i, k]) / s
    return (q[0], q[1], q[2], q[3])


def transform(stamp: float, parent: str, child: str, xyz: tuple[float, float, float],
              quat: tuple[float, float, float, float]) -> M.TransformStamped:
    return M.TransformStamped(
        header=header(stamp, parent), child_frame_id=child,
        transform=M.Transform(translation=M.Vector3(x=xyz[0], y=xyz[1], z=xyz[2]),
                              rotation=M.Quaternion(x=quat[0], y=quat[1], z=quat[2], w=quat[3])))


def _compose(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    ax, ay, ayaw = a
    bx, by, byaw = b
    c, s = math.cos(ayaw), math.sin(ayaw)
    return (ax + c * bx - s * by, ay + s * bx + c * by, ayaw + byaw)


def _inverse(a: tuple[float, float, float]) -> tuple[float, float, float]:
    x, y, yaw = a
    c, s = math.cos(yaw), math.sin(yaw)
    return (-c * x - s * y, s * x - c * y, -yaw)


def camera_mount(camera: Camera) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """Position and optical-frame rotation (x right, y down, z forward) in the base frame."""
    cfg = camera.config
    heading, pitch = cfg.mount_yaw, cfg.mount_pitch
    forward = np.array([math.cos(heading) * math.cos(pitch), math.sin(heading) * math.cos(pitch), -math.sin(pitch)])
    right = np.array([math.sin(heading), -math.cos(heading), 0.0])
    down = np.cross(forward, right)
    mx, my, mz = (float(v) for v in cfg.mount_xyz)
    return (mx, my, mz), quaternion_from_matrix(np.c_[right, down, forward])


def tf_tree(frames: Any, odom: OdometryReading, true_pose: np.ndarray, lidar: Lidar | None,
            camera: Camera | None) -> M.TFMessage:
    """world -> odom -> base -> (scan, rgb, depth) at the odometry stamp.

    world -> odom is what a perfect localizer would publish: the true pose composed with the
    inverse of the odometry estimate (identity while odometry is ground truth), so that
    world -> base is always the true pose. Mounted sensors follow with fixed transforms.
    """
    stamp = odom.stamp
    out = []
    if frames.world != frames.odom:
        tx, ty, tyaw = (float(v) for v in true_pose)
        correction = _compose((tx, ty, tyaw), _inverse((odom.x, odom.y, odom.yaw)))
        out.append(transform(stamp, frames.world, frames.odom, (correction[0], correction[1], 0.0), quaternion_of_yaw(correction[2])))
    out.append(transform(stamp, frames.odom, frames.robot_base, (odom.x, odom.y, 0.0), quaternion_of_yaw(odom.yaw)))
    if lidar is not None:
        cfg = lidar.config
        z = cfg.mount_z if cfg.mount_z is not None else lidar.robot.spec.lidar_height
        out.append(transform(stamp, frames.robot_base, frames.scan, (cfg.mount_xy[0], cfg.mount_xy[1], z), quaternion_of_yaw(cfg.mount_yaw)))
    if camera is not None:
        xyz, quat = camera_mount(camera)
        out.append(transform(stamp, frames.robot_base, frames.rgb, xyz, quat))
        if frames.depth != frames.rgb:
            out.append(transform(stamp, frames.robot_base, frames.depth, xyz, quat))
    return M.TFMessage(transforms=out)


def jpeg(reading: CameraReading, quality: int) -> M.CompressedImage:
    """A JPEG CompressedImage (``format="rgb8; jpeg compressed bgr8"``, as ROS image_transport)."""
    from .. import _deps

    PILImage = _deps.pil_image()
    buf = io.BytesIO()
    PILImage.fromarray(reading.rgb).save(buf, format="JPEG", quality=int(quality))
    return M.CompressedImage(header=header(reading.stamp, reading.frame_id), format="rgb8; jpeg compressed bgr8",
                             data=np.frombuffer(buf.getvalue(), dtype=np.uint8))


class CameraMessages:
    """Builds each camera message type once per frame, only if some output wants it."""

    def __init__(self, reading: CameraReading, depth_frame: str, jpeg_quality: int) -> None:
        self.reading, self.depth_frame, self.quality = reading, depth_frame, jpeg_quality
        self._raw: tuple[Any, Any, Any] | None = None

    def _msgs(self) -> tuple[Any, Any, Any]:
        if self._raw is None:
            rgb, depth, info = camera_to_msgs(self.reading)
            depth.header = header(self.reading.stamp, self.depth_frame)
            self._raw = (rgb, depth, info)
        return self._raw

    def for_type(self, key: str, msg_type: type) -> Any:
        rgb, depth, info = self._msgs()
        if key == "camera":
            return jpeg(self.reading, self.quality) if msg_type is M.CompressedImage else rgb
        if key == "depth":
            return depth
        if key == "camera_info":
            return info
        if key == "depth_camera_info":
            return M.CameraInfo(header=depth.header, height=info.height, width=info.width, k=info.k, r=info.r,
                                p=info.p, d=info.d)
        if key == "rgbd":
            return M.RGBD(header=rgb.header, rgb=rgb, depth=depth, rgb_camera_info=info,
                          depth_camera_info=M.CameraInfo(header=depth.header, height=info.height, width=info.width,
                                                         k=info.k, r=info.r, p=info.p, d=info.d))
        raise KeyError(key)


def occupancy_msg(grid: Any, stamp: float, frame: str) -> M.OccupancyGrid:
    """An ``OccupancyGridMap`` (nav core) as a ``nav_msgs/OccupancyGrid``."""
    rows, cols = grid.data.shape
    ox, oy, oyaw = grid.origin
    info = M.MapMetaData(map_load_time=M.Time.from_sec(stamp), resolution=float(grid.resolution), width=cols, height=rows,
                         origin=M.Pose(position=M.Point(x=ox, y=oy, z=0.0), orientation=M.Quaternion.from_yaw(oyaw)))
    return M.OccupancyGrid(header=header(stamp, frame), info=info, data=np.ascontiguousarray(grid.data, dtype=np.int8).reshape(-1))
