"""Messages <-> the numpy types the navigation algorithms take.

One place for every conversion the components need, so that each component module only wires
topics to algorithms. Every reader validates: a NaN pose, an empty scan or a grid whose data
does not match its size is reported by the caller as a bad input, never passed on.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from emos.core import clock
from emos.errors import EmosError
from emos.msgs.geometry import Point, Pose, PoseStamped, Quaternion, Twist, Vector3
from emos.msgs.nav import MapMetaData, OccupancyGrid, Odometry, Path
from emos.msgs.sensor import LaserScan, PointCloud2
from emos.msgs.std import Header, Time

from ..controllers.sensors import LaserScan2D, OccupancyGrid2D
from ..maps.grid import OccupancyGridMap

__all__ = [
    "BadInput", "pose_of", "velocity_of", "scan_of", "points_of", "grid_map_of", "grid2d_of",
    "grid_msg", "path_msg", "path_of", "twist_msg", "twist_of", "goal_of", "pose_stamped", "localized_odometry",
]


class BadInput(EmosError, ValueError):
    """An input message the navigation algorithms cannot use (the message names it)."""


def pose_of(msg: Any) -> np.ndarray:
    """(x, y, yaw) from an Odometry, PoseStamped, Pose or PointStamped-like message."""
    if isinstance(msg, Odometry):
        pose = msg.pose.pose
    elif isinstance(msg, PoseStamped):
        pose = msg.pose
    elif isinstance(msg, Pose):
        pose = msg
    else:
        raise BadInput(f"location: expected Odometry, PoseStamped or Pose, got {type(msg).__name__}")
    out = np.array([pose.position.x, pose.position.y, pose.orientation.yaw()], dtype=np.float64)
    if not np.all(np.isfinite(out)):
        raise BadInput(f"location: pose has NaN/inf values {out.tolist()}")
    return out


def velocity_of(msg: Any) -> np.ndarray | None:
    """Body-frame (vx, vy, omega) from an Odometry (None for pose-only messages)."""
    if not isinstance(msg, Odometry):
        return None
    t = msg.twist.twist
    out = np.array([t.linear.x, t.linear.y, t.angular.z], dtype=np.float64)
    return out if np.all(np.isfinite(out)) else None


def goal_of(msg: Any) -> np.ndarray:
    """A goal: (x, y) from a PointStamped, (x, y, yaw) from a PoseStamped or Odometry."""
    from emos.msgs.geometry import PointStamped

    if isinstance(msg, PointStamped):
        out = np.array([msg.point.x, msg.point.y], dtype=np.float64)
    else:
        out = pose_of(msg)
    if not np.all(np.isfinite(out)):
        raise BadInput(f"goal: NaN/inf coordinates {out.tolist()}")
    return out


def scan_of(msg: LaserScan) -> LaserScan2D:
    """A LaserScan as the algorithms' LaserScan2D. NaN beams stay NaN (ignored), +inf is a
    free ray, -inf and negative ranges are invalid readings and become NaN."""
    r = np.asarray(msg.ranges, dtype=np.float64)
    if r.size == 0:
        raise BadInput("sensor_data: empty LaserScan (no ranges)")
    if not (math.isfinite(msg.angle_min) and math.isfinite(msg.angle_increment)):
        raise BadInput(f"sensor_data: LaserScan angles are not finite (angle_min={msg.angle_min}, increment={msg.angle_increment})")
    bad = ~np.isnan(r) & ((r < 0) | np.isneginf(r))
    if bad.any():
        r = r.copy()
        r[bad] = np.nan
    range_max = float(msg.range_max) if math.isfinite(msg.range_max) and msg.range_max > max(msg.range_min, 0.0) else math.inf
    range_min = float(msg.range_min) if math.isfinite(msg.range_min) and msg.range_min >= 0 else 0.0
    inc = float(msg.angle_increment) or (2.0 * math.pi / r.size)
    return LaserScan2D(ranges=r, angle_min=float(msg.angle_min), angle_increment=inc, range_min=range_min, range_max=range_max)


def points_of(msg: PointCloud2) -> np.ndarray:
    """(N, 3) finite points of a cloud."""
    pts = msg.xyz().astype(np.float64)
    return pts[np.all(np.isfinite(pts), axis=1)]


def grid_map_of(msg: OccupancyGrid, what: str = "map") -> OccupancyGridMap:
    """A world-frame grid message (the global map; ``what`` names it in errors) as an OccupancyGridMap."""
    info = msg.info
    if info.width == 0 or info.height == 0:
        raise BadInput(f"{what}: empty OccupancyGrid (width or height is 0)")
    o = info.origin
    return OccupancyGridMap.from_flat(msg.data, int(info.width), int(info.height), float(info.resolution),
                                      (o.position.x, o.position.y, o.orientation.yaw()), msg.header.frame_id or "map")


def grid2d_of(msg: OccupancyGrid) -> OccupancyGrid2D:
    """An ego-centric (robot-frame) local map message as the controllers' OccupancyGrid2D."""
    info = msg.info
    if info.width * info.height != msg.data.size or msg.data.size == 0:
        raise BadInput(f"local_map: {info.width}x{info.height} grid with {msg.data.size} cells")
    return OccupancyGrid2D(msg.grid(), float(info.resolution), (info.origin.position.x, info.origin.position.y))


def grid_points_in_robot_frame(msg: OccupancyGrid, pose: np.ndarray, max_range: float = math.inf,
                               occupied_threshold: int = 50) -> np.ndarray:
    """Centres (M, 2) of the occupied cells of a grid that is not ego-centric (its origin is a
    pose in the frame ``pose`` is in, e.g. a map or an obstacle memory in ``map``), in the
    frame of the robot at ``pose``, those within ``max_range`` m of it. Placed by the grid's
    own origin, so a grid never moves with the robot's pose of another instant (an ego-centric
    map built at the last scan, read with the pose of the scan before, lands a scan's motion
    away). Only the cells of the square around the robot are looked at: a large map costs no
    more than a small one."""
    info = msg.info
    if info.width * info.height != msg.data.size or msg.data.size == 0:
        raise BadInput(f"local_map: {info.width}x{info.height} grid with {msg.data.size} cells")
    res = float(info.resolution)
    o = info.origin
    oyaw = o.orientation.yaw()
    co, so = math.cos(oyaw), math.sin(oyaw)
    grid = msg.grid()
    r0, c0 = 0, 0
    if math.isfinite(max_range):
        # The robot in grid cells, and the square of cells that can lie within max_range of it.
        dx, dy = pose[0] - o.position.x, pose[1] - o.position.y
        col, row = (co * dx + so * dy) / res, (-so * dx + co * dy) / res
        reach = max_range / res + 1.0
        r0, r1 = max(int(math.floor(row - reach)), 0), min(int(math.ceil(row + reach)), grid.shape[0])
        c0, c1 = max(int(math.floor(col - reach)), 0), min(int(math.ceil(col + reach)), grid.shape[1])
        if r0 >= r1 or c0 >= c1:
            return np.zeros((0, 2))
        grid = grid[r0:r1, c0:c1]
    rows, cols = np.nonzero(grid >= occupied_threshold)
    gx, gy = (cols + c0 + 0.5) * res, (rows + r0 + 0.5) * res
    wx, wy = o.position.x + co * gx - so * gy, o.position.y + so * gx + co * gy
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dx, dy = wx - pose[0], wy - pose[1]
    out = np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)
    if math.isfinite(max_range):
        out = out[np.einsum("ij,ij->i", out, out) <= max_range * max_range]
    return out


def grid_msg(data: np.ndarray, resolution: float, origin: tuple[float, float, float] | np.ndarray, frame_id: str) -> OccupancyGrid:
    rows, cols = data.shape
    stamp = clock.stamp()  # the node's clock, as every stamp a component writes (simulated under a simulator)
    info = MapMetaData(map_load_time=stamp, resolution=float(resolution), width=cols, height=rows,
                       origin=Pose(position=Point(x=float(origin[0]), y=float(origin[1])), orientation=Quaternion.from_yaw(float(origin[2]))))
    return OccupancyGrid(header=Header(stamp=stamp, frame_id=frame_id), info=info,
                         data=np.ascontiguousarray(data, dtype=np.int8).reshape(-1))


def pose_stamped(x: float, y: float, yaw: float, frame_id: str, stamp: Time | None = None) -> PoseStamped:
    return PoseStamped(header=Header(stamp=stamp or clock.stamp(), frame_id=frame_id),
                       pose=Pose(position=Point(x=float(x), y=float(y)), orientation=Quaternion.from_yaw(float(yaw))))


def localized_odometry(corrected: PoseStamped, measured: Odometry, child_frame_id: str) -> Odometry:
    """A corrected pose (``corrected``, in the map frame) as an Odometry that carries the measured
    twist of ``measured``, the odometry it corrects. Odometry twists are body-frame (ROS REP 105:
    in ``child_frame_id``; vx forward m/s, omega counter-clockwise rad/s), and a map correction
    moves and turns the pose, not the body: the twist is copied unchanged, never rotated."""
    if not isinstance(measured, Odometry):
        raise BadInput(f"a localized pose with a measured twist needs the odometry it corrects, got {type(measured).__name__}")
    out = Odometry(header=corrected.header, child_frame_id=child_frame_id)
    out.pose.pose = corrected.pose
    out.twist.twist = measured.twist.twist
    return out


def path_msg(poses: np.ndarray, frame_id: str) -> Path:
    """(N, 2|3) poses -> Path (yaw 0 when only x, y are given)."""
    stamp = clock.stamp()
    arr = np.asarray(poses, dtype=np.float64)
    yaw = arr[:, 2] if arr.shape[1] > 2 else np.zeros(len(arr))
    return Path(header=Header(stamp=stamp, frame_id=frame_id),
                poses=[pose_stamped(p[0], p[1], a, frame_id, stamp) for p, a in zip(arr, yaw)])


def path_of(msg: Path) -> np.ndarray:
    """Path -> (N, 3) poses; an empty path is an (0, 3) array."""
    out = np.array([(p.pose.position.x, p.pose.position.y, p.pose.orientation.yaw()) for p in msg.poses], dtype=np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(out)):
        raise BadInput("plan: the path has NaN/inf poses")
    return out


def twist_msg(cmd: np.ndarray) -> Twist:
    return Twist(linear=Vector3(x=float(cmd[0]), y=float(cmd[1])), angular=Vector3(z=float(cmd[2])))


def twist_of(msg: Any) -> np.ndarray:
    """(vx, vy, omega) from a Twist or TwistStamped; NaN/inf is a bad input."""
    t = getattr(msg, "twist", msg)
    out = np.array([t.linear.x, t.linear.y, t.angular.z], dtype=np.float64)
    if not np.all(np.isfinite(out)):
        raise BadInput(f"command: NaN/inf velocity {out.tolist()}")
    return out
