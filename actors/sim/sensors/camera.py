"""RGB + depth camera rendered with pybullet's TinyRenderer (works headless, no GPU)."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import attrs
import numpy as np

from emos.config import validators as V

from .. import _deps
from .base import Sensor

if TYPE_CHECKING:
    from ..body import SimRobot


@attrs.define(frozen=True)
class CameraConfig:
    """Pinhole camera. ``vfov_deg`` is the vertical field of view; pixels are square."""

    width: int = attrs.field(default=320, converter=int, validator=V.int_at_least(1))
    height: int = attrs.field(default=240, converter=int, validator=V.int_at_least(1))
    vfov_deg: float = attrs.field(default=60.0, converter=float, validator=V.number(ge=1, lt=179))
    near: float = attrs.field(default=0.05, converter=float)
    far: float = attrs.field(default=20.0, converter=float)
    rate_hz: float = attrs.field(default=10.0, converter=float, validator=V.finite_positive)
    # Mount in the base frame: position (m) and yaw / pitch (rad, pitch > 0 looks down).
    mount_xyz: tuple[float, float, float] = attrs.field(default=(0.2, 0.0, 0.4), converter=lambda v: tuple(float(x) for x in v))
    mount_yaw: float = attrs.field(default=0.0, converter=float)
    mount_pitch: float = attrs.field(default=0.0, converter=float)
    frame_id: str = "camera_optical"

    def __attrs_post_init__(self) -> None:
        if not 0 < self.near < self.far:
            raise ValueError(f"CameraConfig needs 0 < near < far, got near={self.near!r}, far={self.far!r}")
        if abs(self.mount_pitch) >= math.pi / 2:
            raise ValueError(f"CameraConfig.mount_pitch must be within (-pi/2, pi/2), got {self.mount_pitch!r}")

    def intrinsics(self) -> np.ndarray:
        """K (3x3) in ROS pixel convention: pixel (0, 0) is the centre of the top-left pixel."""
        f = (self.height / 2) / math.tan(math.radians(self.vfov_deg) / 2)
        return np.array([[f, 0.0, (self.width - 1) / 2], [0.0, f, (self.height - 1) / 2], [0.0, 0.0, 1.0]])

    def projection_matrix(self) -> list[float]:
        pb = _deps.pybullet()
        return list(pb.computeProjectionMatrixFOV(self.vfov_deg, self.width / self.height, self.near, self.far))


@attrs.define(frozen=True, eq=False)
class CameraReading:
    """An RGB frame (H, W, 3 uint8), its metric depth (H, W float32, +inf = nothing) and K."""

    stamp: float
    frame_id: str
    rgb: np.ndarray
    depth: np.ndarray
    k: np.ndarray
    # Camera pose in the world: position and rotation matrix whose columns are the optical
    # frame's x (right), y (down), z (forward) axes.
    position: np.ndarray
    rotation: np.ndarray

    def point_cloud(self, stride: int = 1, world_frame: bool = False) -> np.ndarray:
        """(N, 3) float32 points from the depth image (optical frame unless ``world_frame``)."""
        return depth_to_points(self.depth[::stride, ::stride], self.k, stride,
                               (self.position, self.rotation) if world_frame else None)

    def to_msgs(self) -> tuple[Any, Any, Any]:
        """(rgb Image, depth Image, CameraInfo) as ``emos.msgs`` objects."""
        from ..msgs import camera_to_msgs

        return camera_to_msgs(self)


def depth_to_points(depth: np.ndarray, k: np.ndarray, stride: int = 1,
                    pose: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Back-project a (possibly strided) depth image through K; drops pixels without depth."""
    h, w = depth.shape
    v, u = np.mgrid[0:h, 0:w]
    u, v = u * stride, v * stride
    ok = np.isfinite(depth)
    z = depth[ok].astype(float)
    x = (u[ok] - k[0, 2]) * z / k[0, 0]
    y = (v[ok] - k[1, 2]) * z / k[1, 1]
    pts = np.c_[x, y, z]
    if pose is not None:
        position, rotation = pose
        pts = pts @ rotation.T + position
    return pts.astype(np.float32)


class Camera(Sensor):
    def __init__(self, robot: SimRobot, config: CameraConfig | None = None, name: str = "camera") -> None:
        super().__init__(robot, name)
        self.config = config or CameraConfig()
        self.rate_hz = self.config.rate_hz
        self._projection: list[float] | None = None

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Camera position and optical-frame rotation in the world."""
        x, y, yaw = self.robot.pose
        mx, my, mz = self.config.mount_xyz
        c, s = math.cos(yaw), math.sin(yaw)
        position = np.array([x + c * mx - s * my, y + s * mx + c * my, mz])
        heading, pitch = yaw + self.config.mount_yaw, self.config.mount_pitch
        forward = np.array([math.cos(heading) * math.cos(pitch), math.sin(heading) * math.cos(pitch), -math.sin(pitch)])
        right = np.array([math.sin(heading), -math.cos(heading), 0.0])
        down = np.cross(forward, right)
        return position, np.c_[right, down, forward]

    def read(self, stamp: float) -> CameraReading:
        cfg, pb = self.config, _deps.pybullet()
        client = self.bound_world.client
        if self._projection is None:
            self._projection = cfg.projection_matrix()
        position, rotation = self.pose()
        forward, down = rotation[:, 2], rotation[:, 1]
        view = client.computeViewMatrix(position.tolist(), (position + forward).tolist(), (-down).tolist())
        _, _, rgba, depth_buffer, _ = client.getCameraImage(
            cfg.width, cfg.height, viewMatrix=view, projectionMatrix=self._projection,
            renderer=pb.ER_TINY_RENDERER,
        )
        rgba = np.asarray(rgba, dtype=np.uint8).reshape(cfg.height, cfg.width, 4)
        d = np.asarray(depth_buffer, dtype=float).reshape(cfg.height, cfg.width)
        # OpenGL depth buffer -> eye-space distance along the optical axis.
        z = cfg.far * cfg.near / (cfg.far - (cfg.far - cfg.near) * d)
        z = np.where(d >= 1.0 - 1e-7, np.inf, z).astype(np.float32)
        return CameraReading(stamp=stamp, frame_id=cfg.frame_id, rgb=np.ascontiguousarray(rgba[:, :, :3]),
                             depth=z, k=cfg.intrinsics(), position=position, rotation=rotation)
