"""Mapping with scan matching: an obstacle memory over a fixed world window, built from scans
placed at the odometry pose corrected by matching each scan against the memory so far.

The pieces of the mapless navigator's global layer (``HitGrid``, ``ScanMatcher``), usable on
their own: the LocalMapper's mapping mode runs this and publishes the memory as a map and the
corrected pose, so a Planner can plan on what the robot has seen.
"""
from __future__ import annotations

import math

import numpy as np

from emos.geometry import wrap_angle

from ..controllers.sensors import LaserScan2D
from .evidence import EvidenceGrid
from .hit_grid import HitGrid
from .scan_matching import ScanMatcher, compose, correction_between

__all__ = ["MemoryMapper"]


class MemoryMapper:
    """``update(scan, odom_pose)`` -> corrected pose; ``grid`` holds the obstacle memory.

    ``bounds`` (xmin, ymin, xmax, ymax) of the world window (m); ``sensor_pose`` (x, y, yaw) of
    the scanner on the robot; ``scan_matching`` False trusts odometry. ``carve_range`` > 0 (m)
    clears remembered cells that beams pass through (moved obstacles, drift ghosts).
    ``evidence_cap`` (scans): forget by evidence instead (``EvidenceGrid``: a cell is released
    after that many more scans saw through it than hit it, within ``free_range`` m), for
    worlds where obstacles move; None (default) never forgets. ``match_margin``: how much a
    scan match must raise the mean likelihood over the odometry's guess to be adopted (0.01).

    ``update_distance`` (m) / ``update_angle`` (rad): a never-forgetting memory (no
    ``evidence_cap``) takes a scan's hits in only once the corrected pose has moved or turned
    that much since the last scan it took in (Hector SLAM's ``map_update_distance_thresh`` /
    ``map_update_angle_thresh``, gmapping's ``linearUpdate``); every scan is still matched and
    corrects the pose. Why: at 50 scans/s a slipping wheel odometry is off by a millimetre or
    two per scan, far below what a match on 5 cm cells can tell apart, so a memory that takes
    in every scan takes each one in at the pose the matcher could not correct, smears every
    obstacle along the robot's motion, and the next scan fits the smear as well as the truth:
    the estimate follows the odometry's drift (1 m and more over a BARN run). Between updates
    the memory stays as sharp as it was, and the drift since the last one (a few cm) is
    large enough to be matched away. 0 and 0 take in every scan (the former behaviour).
    """

    def __init__(self, bounds: tuple[float, float, float, float], resolution: float = 0.05,
                 sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0), scan_matching: bool = True,
                 carve_range: float = 0.0, evidence_cap: int | None = None, free_range: float = 8.0,
                 match_margin: float = 0.01, update_distance: float = 0.2, update_angle: float = 0.2) -> None:
        for name, value in (("match_margin", match_margin), ("update_distance", update_distance), ("update_angle", update_angle)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise ValueError(f"MemoryMapper.{name}: expected a finite number >= 0, got {value!r}")
        self.match_margin = float(match_margin)
        self.update_distance, self.update_angle = float(update_distance), float(update_angle)
        self._last_update: np.ndarray | None = None  # corrected pose of the last scan taken in
        if evidence_cap is not None and carve_range > 0:
            raise ValueError("MemoryMapper: give carve_range or evidence_cap, not both (two ways of forgetting)")
        self.grid: HitGrid = (HitGrid(bounds, resolution) if evidence_cap is None
                              else EvidenceGrid(bounds, resolution, cap=evidence_cap))
        self.free_range = float(free_range)
        self._scans = 0
        self.sensor_pose = sensor_pose
        self.matcher = ScanMatcher() if scan_matching else None
        self.carve_range = float(carve_range)
        self.correction = np.zeros(3)  # map <- odometry

    def update(self, scan: LaserScan2D, odom_pose: np.ndarray) -> np.ndarray:
        odom_pose = np.asarray(odom_pose, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(odom_pose)):
            raise ValueError(f"odom_pose: expected finite (x, y, yaw), got {odom_pose.tolist()}")
        mx, my, myaw = self.sensor_pose
        cm, sm = math.cos(myaw), math.sin(myaw)
        p = scan.points()  # sensor frame, finite hits only
        local = np.c_[mx + cm * p[:, 0] - sm * p[:, 1], my + sm * p[:, 0] + cm * p[:, 1]]
        pose = compose(self.correction, odom_pose)
        if self.matcher is not None and len(local):
            matched, best, at_guess = self.matcher.match(self.grid, pose, local)
            if best > at_guess + self.match_margin:
                self.correction = correction_between(matched, odom_pose)
                pose = matched
        c, s = math.cos(pose[2]), math.sin(pose[2])
        if not isinstance(self.grid, EvidenceGrid) and not self._due(pose):
            return pose
        if isinstance(self.grid, EvidenceGrid):
            self._scans += 1
            sx, sy, syaw = pose[0] + c * mx - s * my, pose[1] + s * mx + c * my, pose[2] + myaw
            angles = syaw + scan.beam_angles()
            r = scan.ranges
            usable = ~np.isnan(r)
            free = self.free_range
            length = np.where(np.isfinite(r), np.minimum(r, free) - 1.5 * self.grid.resolution, free)
            self.grid.observe_free((sx, sy), np.c_[np.cos(angles), np.sin(angles)][usable],
                                   np.maximum(length[usable], 0.0), float(self._scans))
        elif self.carve_range > 0:
            sx, sy, syaw = pose[0] + c * mx - s * my, pose[1] + s * mx + c * my, pose[2] + myaw
            angles = syaw + scan.beam_angles()
            r = scan.ranges
            usable = ~np.isnan(r)
            length = np.where(np.isfinite(r), np.minimum(r, self.carve_range) - 1.5 * self.grid.resolution, self.carve_range)
            self.grid.carve((sx, sy), np.c_[np.cos(angles), np.sin(angles)][usable], np.maximum(length[usable], 0.0))
        self.grid.insert(np.c_[pose[0] + c * local[:, 0] - s * local[:, 1], pose[1] + s * local[:, 0] + c * local[:, 1]])
        return pose

    def _due(self, pose: np.ndarray) -> bool:
        """Whether the memory takes this scan in: the first one, and then once the pose has
        moved ``update_distance`` or turned ``update_angle`` since the last one taken in."""
        last = self._last_update
        if (last is not None and math.hypot(pose[0] - last[0], pose[1] - last[1]) < self.update_distance
                and abs(wrap_angle(float(pose[2] - last[2]))) < self.update_angle):
            return False
        self._last_update = pose.copy()
        return True

    def occupancy(self) -> np.ndarray:
        """The memory as int8 cells: 100 where a beam ended, 0 elsewhere (rows = y)."""
        return np.where(self.grid.occupied, 100, 0).astype(np.int8)
