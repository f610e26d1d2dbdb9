"""Pieces shared by the vision followers: detections, camera intrinsics, lost-target search."""
from __future__ import annotations

import math

import attrs
import numpy as np

from emos.config import validators as V

from ..robot import RobotConfig
from .base import ControlStatus

__all__ = ["BoundingBox", "CameraIntrinsics", "TargetSearch", "median_depth"]


@attrs.define(frozen=True)
class BoundingBox:
    """A 2D detection in pixels: top-left corner (x, y), size (width, height), image size."""

    x: float = attrs.field(converter=float)
    y: float = attrs.field(converter=float)
    width: float = attrs.field(converter=float, validator=V.finite_positive)
    height: float = attrs.field(converter=float, validator=V.finite_positive)
    image_width: int = attrs.field(converter=int, validator=V.finite_positive)
    image_height: int = attrs.field(converter=int, validator=V.finite_positive)

    @property
    def center(self) -> tuple[float, float]:
        return self.x + 0.5 * self.width, self.y + 0.5 * self.height

    @property
    def horizontal_error(self) -> float:
        """Offset of the box centre from the image centre, in [-1, 1] (positive: right)."""
        return (self.center[0] - 0.5 * self.image_width) / (0.5 * self.image_width)

    @property
    def relative_size(self) -> float:
        """Box height as a fraction of the image height (a proxy for inverse distance)."""
        return self.height / self.image_height


@attrs.define(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics (pixels), as in a CameraInfo K matrix."""

    fx: float = attrs.field(converter=float, validator=V.finite_positive)
    fy: float = attrs.field(converter=float, validator=V.finite_positive)
    cx: float = attrs.field(converter=float)
    cy: float = attrs.field(converter=float)

    def back_project(self, u: np.ndarray | float, v: np.ndarray | float, depth: np.ndarray | float) -> np.ndarray:
        """Pixels and depth (m) -> points in the optical frame (x right, y down, z forward)."""
        z = np.asarray(depth, dtype=np.float64)
        return np.stack([(np.asarray(u) - self.cx) * z / self.fx, (np.asarray(v) - self.cy) * z / self.fy, z], axis=-1)


def median_depth(depth_image: np.ndarray, u: float, v: float, half_width: float, half_height: float) -> float | None:
    """Median of the valid depths (finite, > 0) in the window of ``half_width`` x ``half_height``
    pixels around (u, v), clipped to the image; None when the window holds no valid depth.

    The median over a window, not the pixel under the point, ignores depth holes and the
    background that a box's edges or a slightly-off point catch.
    """
    depth = np.asarray(depth_image)
    if depth.ndim != 2:
        raise ValueError(f"depth_image: expected a 2D array, got shape {depth.shape}")
    r0, r1 = int(max(0, math.floor(v - half_height))), int(min(depth.shape[0], math.ceil(v + half_height)))
    c0, c1 = int(max(0, math.floor(u - half_width))), int(min(depth.shape[1], math.ceil(u + half_width)))
    patch = depth[r0:r1, c0:c1].astype(np.float64)
    valid = patch[np.isfinite(patch) & (patch > 0)]
    return float(np.median(valid)) if valid.size else None


class TargetSearch:
    """What to do while the target is missing: wait, then rotate to look for it, then give up.

    ``pause_steps`` control steps of standstill first (detections may just be late), then, if
    enabled, an in-place rotation towards the side the target was last seen on, until
    ``timeout`` seconds of search have passed.
    """

    def __init__(self, robot: RobotConfig, dt: float, pause_steps: float, timeout: float, enabled: bool) -> None:
        self.robot = robot
        self.dt = dt
        self.pause_steps = pause_steps
        self.timeout = timeout
        self.enabled = enabled
        self.lost_steps = 0
        self.last_side = 1.0

    def seen(self, side: float) -> None:
        self.lost_steps = 0
        if side != 0.0:
            self.last_side = math.copysign(1.0, side)

    def step(self) -> tuple[np.ndarray, ControlStatus]:
        self.lost_steps += 1
        if self.lost_steps <= self.pause_steps:
            return np.zeros(3), ControlStatus.WAITING
        searching_for = (self.lost_steps - self.pause_steps) * self.dt
        if not self.enabled or searching_for > self.timeout:
            return np.zeros(3), ControlStatus.LOST
        w = 0.5 * self.robot.ctrl_omega_limits.max_vel
        if self.robot.model_type.name == "ACKERMANN":
            # A car cannot spin: search by driving a slow tight circle.
            v = 0.3 * self.robot.ctrl_vx_limits.max_vel
            return np.array([v, 0.0, self.last_side * min(w, v * self.robot.max_curvature)]), ControlStatus.SEARCHING
        return np.array([0.0, 0.0, self.last_side * w]), ControlStatus.SEARCHING
