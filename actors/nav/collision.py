"""Collision checking between the robot body and an occupancy grid with python-fcl.

The robot's ``RobotGeometry`` becomes an fcl shape; the occupied cells of the map become fcl
boxes, merged into maximal rectangles first (a wall of 200 cells is one box, not 200), held in
a ``DynamicAABBTreeCollisionManager``. Obstacle boxes are much taller than the robot and
centred at z = 0 like the robot, so a 3D fcl query answers the 2D question "does the robot's
footprint (the shape's horizontal projection) overlap an occupied cell" exactly.

A distance map (exact EDT) gives a conservative shortcut: poses far from every obstacle are
valid and poses whose centre is deep inside one are invalid without calling fcl; everything
in between goes to fcl. ``is_valid_exact`` always calls fcl (used to verify final paths).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from emos.actors.nav.maps.edt import euclidean_distance_transform
from emos.actors.nav.maps.grid import OccupancyGridMap
from emos.actors.nav.robot import RobotGeometry

__all__ = ["geometry_to_fcl", "occupied_rectangles", "MapCollisionChecker"]

_SQRT2 = math.sqrt(2.0)


def _fcl() -> Any:
    try:
        import fcl
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("collision checking needs python-fcl: pip install 'emos[nav]'") from exc
    return fcl


def geometry_to_fcl(geometry_type: Any, geometry_params: Any) -> Any:
    """fcl shape for a ``RobotGeometry.Type`` and its parameter array (see ``RobotGeometry``).

    BOX [length, width, height] -> Box; CYLINDER [radius, length_z] -> Cylinder;
    SPHERE [radius] -> Sphere; ELLIPSOID [axis_x, axis_y, axis_z] (semi-axes) -> Ellipsoid;
    CAPSULE [radius, length_z] -> Capsule; CONE [radius, length_z] -> Cone.
    """
    fcl = _fcl()
    gtype = RobotGeometry.get_type(geometry_type)
    p = [float(v) for v in RobotGeometry.validate_params(gtype, geometry_params)]
    T = RobotGeometry.Type
    makers = {
        T.BOX: lambda: fcl.Box(p[0], p[1], p[2]),
        T.CYLINDER: lambda: fcl.Cylinder(p[0], p[1]),
        T.SPHERE: lambda: fcl.Sphere(p[0]),
        T.ELLIPSOID: lambda: fcl.Ellipsoid(p[0], p[1], p[2]),
        T.CAPSULE: lambda: fcl.Capsule(p[0], p[1]),
        T.CONE: lambda: fcl.Cone(p[0], p[1]),
    }
    return makers[gtype]()


def occupied_rectangles(mask: np.ndarray) -> np.ndarray:
    """Cover the ``True`` cells of a 2D mask with disjoint axis-aligned rectangles.

    Returns (K, 4) int64 rows ``[ix0, iy0, ix1, iy1)`` (half-open cell ranges). Horizontal runs
    are found per row, then identical runs on consecutive rows are stacked into one rectangle;
    both steps are vectorized.
    """
    m = np.asarray(mask, dtype=bool)
    if m.ndim != 2:
        raise ValueError(f"occupied_rectangles: expected a 2D mask, got shape {m.shape}")
    h, w = m.shape
    padded = np.zeros((h, w + 2), dtype=np.int8)
    padded[:, 1:-1] = m
    edges = np.diff(padded, axis=1)
    start_r, start_c = np.nonzero(edges == 1)
    end_r, end_c = np.nonzero(edges == -1)
    if start_r.size == 0:
        return np.zeros((0, 4), dtype=np.int64)
    # nonzero scans row-major, so starts and ends pair up in order.
    runs = np.stack((start_r, start_c, end_c), axis=1)
    order = np.lexsort((runs[:, 0], runs[:, 2], runs[:, 1]))  # by c0, then c1, then row
    runs = runs[order]
    same_span = np.zeros(len(runs), dtype=bool)
    same_span[1:] = (
        (runs[1:, 1] == runs[:-1, 1]) & (runs[1:, 2] == runs[:-1, 2]) & (runs[1:, 0] == runs[:-1, 0] + 1)
    )
    # After sorting, each rectangle is a contiguous block of runs: first/last index it.
    first = np.nonzero(~same_span)[0]
    last = np.r_[first[1:] - 1, len(runs) - 1]
    return np.stack(
        (runs[first, 1], runs[first, 0], runs[first, 2], runs[last, 0] + 1), axis=1
    ).astype(np.int64)


def _yaw_rotation(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class MapCollisionChecker:
    """Robot-vs-occupancy-grid collision and distance queries for SE2 poses (x, y, yaw).

    ``occupied_threshold``: cells with a value >= this are obstacles. ``unknown_is_occupied``:
    unknown cells (-1) and everything outside the grid are obstacles too (the safe default for
    global planning); otherwise only the robot centre must lie inside the grid.
    """

    def __init__(
        self,
        grid: OccupancyGridMap,
        geometry_type: Any,
        geometry_params: Any,
        *,
        occupied_threshold: int = 65,
        unknown_is_occupied: bool = True,
    ) -> None:
        if not isinstance(grid, OccupancyGridMap):
            raise TypeError(f"MapCollisionChecker: grid must be an OccupancyGridMap, got {type(grid).__name__}")
        fcl = _fcl()
        self._fcl = fcl
        self.grid = grid
        self.geometry_type = RobotGeometry.get_type(geometry_type)
        self.geometry_params = RobotGeometry.validate_params(self.geometry_type, geometry_params)
        self.outer_radius = RobotGeometry.radius(self.geometry_type, self.geometry_params)
        self.inner_radius = RobotGeometry.inner_radius(self.geometry_type, self.geometry_params)
        self.occupied_threshold = int(occupied_threshold)
        self.unknown_is_occupied = bool(unknown_is_occupied)

        mask = grid.occupied_mask(self.occupied_threshold, self.unknown_is_occupied)
        self.rectangles = occupied_rectangles(mask)
        # Tall obstacles: the 3D query then equals the 2D footprint query for any robot height.
        self._obstacle_height = 4.0 * RobotGeometry.height(self.geometry_type, self.geometry_params) + 2.0
        objects = [self._box_object(*r) for r in self.rectangles]
        if self.unknown_is_occupied:
            objects.extend(self._border_objects())
        self._manager = fcl.DynamicAABBTreeCollisionManager()
        if objects:
            self._manager.registerObjects(objects)
        self._manager.setup()
        self._objects = objects  # keep python references alive for the manager
        self._robot = fcl.CollisionObject(geometry_to_fcl(self.geometry_type, self.geometry_params), fcl.Transform())

        # Distance map for the shortcut; with unknown_is_occupied the outside counts as obstacle.
        if self.unknown_is_occupied:
            padded = np.pad(mask, 1, constant_values=True)
            self.distance_map = euclidean_distance_transform(padded, grid.resolution)[1:-1, 1:-1]
        else:
            self.distance_map = euclidean_distance_transform(mask, grid.resolution)
        res = grid.resolution
        # Clearance of any point of a cell >= D - res*sqrt(2) (half diagonal at both ends).
        self._free_above = self.outer_radius + res * _SQRT2
        # Distance to the nearest obstacle's square <= D + res*sqrt(2)/2.
        self._blocked_below = self.inner_radius - res * _SQRT2 / 2.0
        c, s = math.cos(grid.origin[2]), math.sin(grid.origin[2])
        self._rot = (c, s)
        self.fcl_calls = 0

    @classmethod
    def from_robot(cls, grid: OccupancyGridMap, robot: Any, **kwargs: Any) -> MapCollisionChecker:
        """Build from a ``RobotConfig`` (uses its geometry_type and geometry_params)."""
        return cls(grid, robot.geometry_type, robot.geometry_params, **kwargs)

    # ---- obstacle construction --------------------------------------------------------
    def _box_object(self, ix0: int, iy0: int, ix1: int, iy1: int) -> Any:
        res = self.grid.resolution
        center_map = np.array([(ix0 + ix1) * 0.5 * res, (iy0 + iy1) * 0.5 * res])
        center = self.grid.map_to_world(center_map)
        box = self._fcl.Box((ix1 - ix0) * res, (iy1 - iy0) * res, self._obstacle_height)
        tf = self._fcl.Transform(_yaw_rotation(self.grid.origin[2]), np.array([center[0], center[1], 0.0]))
        return self._fcl.CollisionObject(box, tf)

    def _border_objects(self) -> list[Any]:
        """Four slabs just outside the grid so the outside counts as an obstacle."""
        w, h = self.grid.width, self.grid.height
        t = max(4, int(math.ceil(2 * self.outer_radius / self.grid.resolution)) + 1)
        return [
            self._box_object(-t, -t, w + t, 0),
            self._box_object(-t, h, w + t, h + t),
            self._box_object(-t, 0, 0, h),
            self._box_object(w, 0, w + t, h),
        ]

    @property
    def obstacle_count(self) -> int:
        return len(self._objects)

    # ---- queries ----------------------------------------------------------------------
    def _cell(self, x: float, y: float) -> tuple[int, int] | None:
        ox, oy, _ = self.grid.origin
        c, s = self._rot
        dx, dy = x - ox, y - oy
        res = self.grid.resolution
        ix = math.floor((c * dx + s * dy) / res)
        iy = math.floor((-s * dx + c * dy) / res)
        if 0 <= ix < self.grid.width and 0 <= iy < self.grid.height:
            return ix, iy
        return None

    def _place(self, x: float, y: float, yaw: float) -> None:
        self._robot.setTransform(self._fcl.Transform(_yaw_rotation(yaw), np.array([x, y, 0.0])))

    def collides_exact(self, x: float, y: float, yaw: float) -> bool:
        """fcl collision test of the robot at (x, y, yaw) against every obstacle."""
        self.fcl_calls += 1
        self._place(x, y, yaw)
        data = self._fcl.CollisionData()
        self._manager.collide(self._robot, data, self._fcl.defaultCollisionCallback)
        return bool(data.result.is_collision)

    def is_valid_exact(self, x: float, y: float, yaw: float) -> bool:
        """Valid by fcl alone (plus the centre-in-grid rule); no distance-map shortcut."""
        if self._cell(x, y) is None:
            return False
        return not self.collides_exact(x, y, yaw)

    def is_valid(self, x: float, y: float, yaw: float) -> bool:
        """Valid pose: centre inside the grid and no overlap with any obstacle."""
        cell = self._cell(x, y)
        if cell is None:
            return False
        d = self.distance_map[cell[1], cell[0]]
        if d > self._free_above:
            return True
        if d < self._blocked_below:
            return False
        return not self.collides_exact(x, y, yaw)

    def are_valid(self, poses: np.ndarray, exact: bool = False) -> np.ndarray:
        """Validity of (N, 3) poses. The shortcut is vectorized; only the undecided go to fcl.

        ``exact=True`` sends every in-grid pose to fcl (for verification).
        """
        p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        cells = self.grid.world_to_grid(p[:, :2])
        inside = self.grid.in_bounds(cells)
        out = np.zeros(len(p), dtype=bool)
        d = np.full(len(p), -np.inf)
        d[inside] = self.distance_map[cells[inside, 1], cells[inside, 0]]
        if exact:
            undecided = inside
        else:
            out[inside & (d > self._free_above)] = True
            undecided = inside & (d <= self._free_above) & (d >= self._blocked_below)
        for i in np.nonzero(undecided)[0]:
            out[i] = not self.collides_exact(p[i, 0], p[i, 1], p[i, 2])
        return out

    def min_distance(self, x: float, y: float, yaw: float) -> float:
        """Smallest distance (m) between the robot at (x, y, yaw) and any obstacle; 0 if touching.

        Returns ``inf`` when the map holds no obstacle at all.
        """
        if not self._objects:
            return math.inf
        self._place(x, y, yaw)
        data = self._fcl.DistanceData()
        self._manager.distance(self._robot, data, self._fcl.defaultDistanceCallback)
        return max(0.0, float(data.result.min_distance))

    def clearance_lower_bound(self, poses: np.ndarray) -> np.ndarray:
        """Cheap vectorized lower bound of the clearance (m) of each pose; -inf outside the grid."""
        p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        cells = self.grid.world_to_grid(p[:, :2])
        inside = self.grid.in_bounds(cells)
        out = np.full(len(p), -np.inf)
        out[inside] = self.distance_map[cells[inside, 1], cells[inside, 0]] - self.grid.resolution * _SQRT2 - self.outer_radius
        return out
