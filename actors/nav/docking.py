"""Docking (Nav2's docking server, its algorithms): find a V-shaped charging dock in a laser scan
and drive onto it.

The dock is a V reflector (two arms meeting at the charging contacts, opening toward the robot),
the shape a scan sees from any approach angle. Its frame: origin at the apex, x out of the dock
(toward an approaching robot). The robot is docked at ``(docked_offset, 0)`` of that frame facing
the dock (yaw pi); the staging pose is ``staging_offset`` m further out on the same axis.

* :func:`detect_dock` fits the V's inner faces to the scan points near an estimate of the dock
  pose (a dock database entry carried into the robot frame by the odometry, as Nav2's dock
  plugins take one) with a robust least-squares fit. It needs enough points on BOTH arms (one
  arm alone does not fix the heading) and a small residual; otherwise it says why it failed.
* :class:`DockApproach` is the final-approach control law on the detected dock pose, in the
  robot frame (odometry drift does not matter): pure pursuit onto the dock axis with a
  look-ahead that shrinks with the distance left, a creep speed at the end, and a rotation in
  place for the last degrees of heading. Pure numpy; the ``DockingServer`` component wires it.
"""
from __future__ import annotations

import math

import attrs
import numpy as np

from emos.config import validators as V
from emos.geometry import wrap_angle

__all__ = ["DockSpec", "Detection", "detect_dock", "dock_template", "DockApproach", "compose", "invert"]


@attrs.define(frozen=True)
class DockSpec:
    """The dock as the robot knows it (Nav2: the dock plugin's parameters). Defaults match the
    simulator's ``charging_dock`` shape (actors/sim/builders.py)."""

    half_angle: float = attrs.field(default=math.radians(45.0), converter=float, validator=V.number(gt=0.1, lt=1.45))
    arm_length: float = attrs.field(default=0.4, converter=float, validator=V.finite_positive)
    thickness: float = attrs.field(default=0.03, converter=float, validator=V.finite_positive)
    docked_offset: float = attrs.field(default=0.35, converter=float, validator=V.finite_positive)
    staging_offset: float = attrs.field(default=0.6, converter=float, validator=V.finite_positive)


def compose(a: np.ndarray | tuple, b: np.ndarray | tuple) -> np.ndarray:
    """Pose a (x, y, yaw) composed with pose b given in a's frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap_angle(a[2] + b[2])])


def invert(a: np.ndarray | tuple) -> np.ndarray:
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([-c * a[0] - s * a[1], s * a[0] - c * a[1], wrap_angle(-a[2])])


def dock_template(spec: DockSpec) -> np.ndarray:
    """The two inner faces as segments (2, 2, 2) [arm][start/end][x/y] in the dock frame."""
    x0 = spec.thickness / 2 / math.sin(spec.half_angle)  # where the inner faces meet
    out = np.zeros((2, 2, 2))
    for k, sign in enumerate((1.0, -1.0)):
        d = np.array([math.cos(spec.half_angle), sign * math.sin(spec.half_angle)])
        out[k, 0] = (x0, 0.0)
        out[k, 1] = np.array([x0, 0.0]) + d * (spec.arm_length - spec.thickness)
    return out


def _segment_distance(points: np.ndarray, seg: np.ndarray) -> np.ndarray:
    a, b = seg[0], seg[1]
    ab = b - a
    t = np.clip(((points - a) @ ab) / float(ab @ ab), 0.0, 1.0)
    proj = a + t[:, None] * ab
    return np.linalg.norm(points - proj, axis=1)


def _to_dock(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    d = points - pose[:2]
    return np.c_[c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]]


@attrs.define(frozen=True)
class Detection:
    found: bool
    pose: np.ndarray  # (x, y, yaw) of the dock in the frame of the points
    rms: float
    points: int
    reason: str = ""


def detect_dock(points: np.ndarray, estimate: np.ndarray | tuple, spec: DockSpec, *, search_radius: float = 0.5,
                min_points: int = 8, max_rms: float = 0.02, yaw_starts: tuple[float, ...] = (0.0, 0.35, -0.35)) -> Detection:
    """The dock's pose in the frame of ``points`` (N, 2), searched within ``search_radius`` m of
    ``estimate`` (x, y, yaw), the fit started at its heading plus each of ``yaw_starts`` (a
    tracker that knows the dock well passes ``(0.0,)``). Not found (with the reason) without enough points on both arms or
    with a residual above ``max_rms`` m."""
    from scipy.optimize import least_squares

    est = np.asarray(estimate, dtype=np.float64).reshape(3)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    reach = spec.arm_length + search_radius
    near = pts[np.linalg.norm(pts - est[:2], axis=1) <= reach] if pts.shape[0] else pts
    if near.shape[0] < 2 * min_points:
        return Detection(False, est, math.inf, int(near.shape[0]),
                         f"only {near.shape[0]} scan points within {reach:.2f} m of the expected dock pose "
                         f"({est[0]:.2f}, {est[1]:.2f}): need {2 * min_points}")
    template = dock_template(spec)
    # Only what can be the V under the estimate: in front of the apex (the wall the dock stands
    # against is behind it) and no wider than the arms' span (plus the estimate's error).
    local0 = _to_dock(near, est)
    span = spec.arm_length * math.sin(spec.half_angle) + 0.05
    near = near[(local0[:, 0] > template[0, 0, 0] - 0.02) & (np.abs(local0[:, 1]) <= span)
                & (local0[:, 0] <= spec.arm_length * math.cos(spec.half_angle) + 0.1)]
    if near.shape[0] < 2 * min_points:
        return Detection(False, est, math.inf, int(near.shape[0]),
                         f"only {near.shape[0]} scan points where the V of the dock should be (near the expected pose "
                         f"({est[0]:.2f}, {est[1]:.2f})): need {2 * min_points}")

    def residual(p: np.ndarray) -> np.ndarray:
        local = _to_dock(near, p)
        return np.minimum(_segment_distance(local, template[0]), _segment_distance(local, template[1]))

    best = None
    for dyaw in yaw_starts:
        start = est + np.array([0.0, 0.0, dyaw])
        fit = least_squares(residual, start, loss="soft_l1", f_scale=0.01, max_nfev=200)
        if best is None or fit.cost < best.cost:
            best = fit
    assert best is not None
    # What stands behind the dock (the wall it is against) is not the V: refit on the points in
    # front of the apex and near the arms only, so they neither pull the fit nor count in its rms.
    front = _to_dock(near, best.x)
    keep = (front[:, 0] > template[0, 0, 0] - 0.005) & (residual(best.x) <= 0.05)
    if int(keep.sum()) >= 2 * min_points:
        near = near[keep]
        best = least_squares(residual, best.x, loss="soft_l1", f_scale=0.01, max_nfev=200)
    pose = np.array([best.x[0], best.x[1], wrap_angle(best.x[2])])
    if math.dist(pose[:2], est[:2]) > search_radius:
        return Detection(False, pose, math.inf, 0, f"the best V fit is {math.dist(pose[:2], est[:2]):.2f} m from the "
                                                   f"expected dock pose (search radius {search_radius:g} m)")
    local = _to_dock(near, pose)
    d0, d1 = _segment_distance(local, template[0]), _segment_distance(local, template[1])
    inlier = np.minimum(d0, d1) <= max(3 * max_rms, 0.03)
    on0, on1 = int(np.sum(inlier & (d0 <= d1))), int(np.sum(inlier & (d1 < d0)))
    if min(on0, on1) < min_points:
        return Detection(False, pose, math.inf, on0 + on1,
                         f"the V does not show: {on0} and {on1} scan points on its two arms (need {min_points} on each)")
    rms = float(np.sqrt(np.mean(np.minimum(d0, d1)[inlier] ** 2)))
    if rms > max_rms:
        return Detection(False, pose, rms, on0 + on1, f"the V fit is poor: rms {rms * 100:.1f} cm (limit {max_rms * 100:.1f} cm)")
    return Detection(True, pose, rms, on0 + on1)


@attrs.define
class DockApproach:
    """Final approach onto the docked pose, from the dock pose in the robot frame at each step.
    ``step`` returns (vx, omega, done)."""

    spec: DockSpec
    max_speed: float = 0.15
    min_speed: float = 0.02
    max_omega: float = 0.6
    xy_tolerance: float = 0.004
    yaw_tolerance: float = math.radians(0.5)
    rotating: bool = False

    def docked_pose(self, dock: np.ndarray) -> np.ndarray:
        """The docked pose of the robot in the frame of ``dock`` (robot frame -> robot frame)."""
        return compose(dock, (self.spec.docked_offset, 0.0, math.pi))

    def errors(self, dock: np.ndarray) -> tuple[float, float, float]:
        """(distance left along the dock axis, lateral offset, heading error) of the robot."""
        robot_in_dock = invert(dock)  # the robot's pose in the dock frame
        along = float(robot_in_dock[0] - self.spec.docked_offset)
        return along, float(robot_in_dock[1]), float(wrap_angle(robot_in_dock[2] - math.pi))

    def step(self, dock: np.ndarray) -> tuple[float, float, bool]:
        along, lateral, heading = self.errors(dock)
        if self.rotating or along <= self.xy_tolerance:
            self.rotating = True  # at the contacts' distance: only the heading is left
            if abs(heading) <= self.yaw_tolerance:
                return 0.0, 0.0, True
            return 0.0, float(np.clip(-1.5 * heading, -self.max_omega, self.max_omega)), False
        # Pure pursuit to a point on the dock axis: the look-ahead shrinks with the distance left,
        # so the lateral offset dies out before the contacts (it cannot be fixed once there).
        lookahead = max(0.5 * along, 0.03)
        target_dock = np.array([self.spec.docked_offset + max(along - lookahead, 0.0), 0.0])
        c, s = math.cos(dock[2]), math.sin(dock[2])
        tx, ty = dock[0] + c * target_dock[0] - s * target_dock[1], dock[1] + s * target_dock[0] + c * target_dock[1]
        dist2 = tx * tx + ty * ty
        curvature = 2.0 * ty / max(dist2, 1e-6)
        v = float(np.clip(1.0 * along, self.min_speed, self.max_speed))
        if tx < 0.0 or abs(math.atan2(ty, tx)) > math.radians(60):  # facing away: turn first
            return 0.0, float(np.clip(2.0 * math.atan2(ty, tx), -self.max_omega, self.max_omega)), False
        w = v * curvature
        if abs(w) > self.max_omega:
            v, w = v * self.max_omega / abs(w), math.copysign(self.max_omega, w)
        return v, w, False
