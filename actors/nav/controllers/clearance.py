"""Footprint clearance of many poses against obstacle points (vectorized, no FCL needed).

For the planar footprints the controllers use (circle, rectangle, ellipse) the signed distance
is computed in closed form, which is exact and far cheaper per pose than building FCL objects
for thousands of rollout poses. Circles need one centre distance; rectangles and ellipses are
refined only for obstacle points inside their bounding circle (plus margin).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..robot import RobotConfig, RobotGeometry

__all__ = ["pose_clearance", "trajectory_clearance", "trajectory_min_clearance", "nearby_obstacles", "voxel_downsample", "warm_up"]

_ROUND = (RobotGeometry.Type.CYLINDER, RobotGeometry.Type.SPHERE, RobotGeometry.Type.CAPSULE,
          RobotGeometry.Type.CONE)


def voxel_downsample(points: np.ndarray, cell: float) -> np.ndarray:
    """Keep one point per ``cell`` x ``cell`` square (the first one seen).

    A 720-beam scan puts many hits within millimetres of each other near the robot; one per
    cell keeps the clearance error below ``cell * sqrt(2)`` for a fraction of the cost.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] < 2 or cell <= 0:
        return pts
    keys = np.floor(pts / cell).astype(np.int64)
    keys -= keys.min(axis=0)
    flat = keys[:, 0] * (int(keys[:, 1].max()) + 1) + keys[:, 1]
    _, first = np.unique(flat, return_index=True)
    return pts[np.sort(first)]


def nearby_obstacles(obstacles: np.ndarray, center: np.ndarray, reach: float) -> np.ndarray:
    """Obstacles within ``reach`` of ``center``: rollouts cannot touch anything farther."""
    obs = np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
    if obs.shape[0] == 0:
        return obs
    d2 = (obs[:, 0] - center[0]) ** 2 + (obs[:, 1] - center[1]) ** 2
    return obs[d2 <= reach * reach]


def pose_clearance(robot: RobotConfig, poses: np.ndarray, obstacles: np.ndarray,
                   chunk_pairs: int = 1 << 20) -> np.ndarray:
    """Signed distance from each footprint (poses (..., 3), world) to the nearest obstacle.

    ``inf`` when there are no obstacles; negative when an obstacle is inside the footprint.
    """
    poses = np.asarray(poses, dtype=np.float64)
    lead = poses.shape[:-1]
    flat = poses.reshape(-1, 3)
    obs = np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
    out = np.full(flat.shape[0], np.inf)
    if obs.shape[0] == 0 or flat.shape[0] == 0:
        return out.reshape(lead)
    if flat.shape[0] * obs.shape[0] >= KDTREE_PAIRS:
        tree = _kdtree(obs)
        if tree is not None:
            return _clearance_kdtree(robot, flat, obs, tree).reshape(lead)
    obs32 = obs.astype(np.float32)
    round_shape = robot.geometry_type in _ROUND
    r_out = robot.radius
    r_in = robot.inner_radius
    rows = max(1, chunk_pairs // obs.shape[0])
    for s in range(0, flat.shape[0], rows):
        q = flat[s:s + rows]
        dx = q[:, 0:1].astype(np.float32) - obs32[None, :, 0]
        dy = q[:, 1:2].astype(np.float32) - obs32[None, :, 1]
        d2 = dx * dx + dy * dy
        dmin = np.sqrt(d2.min(axis=1)).astype(np.float64)
        if round_shape:
            out[s:s + rows] = dmin - r_out
            continue
        # Lower bound from the bounding circle; refine only pairs that could be closer.
        res = dmin - r_out
        # An obstacle at centre distance d is at least d - r_out from the footprint, and the
        # nearest one is at most dmin - r_in away: only d <= dmin + r_out - r_in can win.
        bound = (dmin + (r_out - r_in) + 1e-6).astype(np.float32)
        near_pose, near_obs = np.nonzero(d2 <= (bound * bound)[:, None])
        if near_pose.size:
            qp = q[near_pose]
            c, sn = np.cos(qp[:, 2]), np.sin(qp[:, 2])
            wx = obs[near_obs, 0] - qp[:, 0]
            wy = obs[near_obs, 1] - qp[:, 1]
            local = np.stack([c * wx + sn * wy, -sn * wx + c * wy], axis=-1)
            fd = robot.footprint_distance(local)
            exact = np.full(q.shape[0], np.inf)
            np.minimum.at(exact, near_pose, fd)
            res = np.where(np.isfinite(exact), exact, res)
        out[s:s + rows] = res
    return out.reshape(lead)


KDTREE_PAIRS = 20_000  # poses x obstacles from which a k-d tree beats all pairs (DWA: ~10^7 pairs per step)
_NEAREST = 16  # obstacles fetched per pose; poses with more inside their bound are refined in full


_cKDTree: Any = None  # scipy's cKDTree once warm_up() ran; False without scipy (all pairs then)


def warm_up() -> None:
    """Import scipy's k-d tree now. The import takes a good fraction of a second: a controller
    does it when it is built, not in its first control step with enough points to need it, and a
    process that never builds one (most of a run's processes import this module) never pays it."""
    global _cKDTree
    if _cKDTree is None:
        try:
            from scipy.spatial import cKDTree
        except ImportError:  # emos without the nav extra
            _cKDTree = False
        else:
            _cKDTree = cKDTree


def _kdtree(obs: np.ndarray):
    warm_up()
    return _cKDTree(obs) if _cKDTree else None


def _clearance_kdtree(robot: RobotConfig, flat: np.ndarray, obs: np.ndarray, tree) -> np.ndarray:
    """:func:`pose_clearance` through a k-d tree of the obstacles: the same exact distances
    (the nearest centre distance, then the footprint distance of every obstacle that can be
    nearer than the bounding circle says) for a fraction of the pair count."""
    if robot.geometry_type in _ROUND:
        return tree.query(flat[:, :2], k=1)[0] - robot.radius
    k = min(_NEAREST, obs.shape[0])
    dist, idx = tree.query(flat[:, :2], k=k)
    dist, idx = dist.reshape(flat.shape[0], k), idx.reshape(flat.shape[0], k)
    dmin = dist[:, 0]
    bound = dmin + (robot.radius - robot.inner_radius) + 1e-6
    out = dmin - robot.radius
    pose_i, slot = np.nonzero(dist <= bound[:, None])
    # A pose whose k-th nearest is still inside its bound may have more candidates: all of them.
    crowded = np.nonzero(dist[:, -1] <= bound)[0] if k < obs.shape[0] else np.zeros(0, dtype=np.int64)
    if crowded.size:
        keep = ~np.isin(pose_i, crowded)
        pose_i, obs_i = pose_i[keep], idx[pose_i[keep], slot[keep]]
        extra = tree.query_ball_point(flat[crowded, :2], r=bound[crowded])
        counts = np.fromiter((len(e) for e in extra), dtype=np.int64, count=len(extra))
        pose_i = np.concatenate([pose_i, np.repeat(crowded, counts)])
        obs_i = np.concatenate([obs_i, np.concatenate([np.asarray(e, dtype=np.int64) for e in extra])])
    else:
        obs_i = idx[pose_i, slot]
    if pose_i.size:
        qp = flat[pose_i]
        c, sn = np.cos(qp[:, 2]), np.sin(qp[:, 2])
        wx, wy = obs[obs_i, 0] - qp[:, 0], obs[obs_i, 1] - qp[:, 1]
        fd = robot.footprint_distance(np.stack([c * wx + sn * wy, -sn * wx + c * wy], axis=-1))
        exact = np.full(flat.shape[0], np.inf)
        np.minimum.at(exact, pose_i, fd)
        out = np.where(np.isfinite(exact), exact, out)
    return out


def trajectory_clearance(robot: RobotConfig, trajectories: np.ndarray, obstacles: np.ndarray) -> np.ndarray:
    """Smallest footprint clearance along each trajectory (T, P, 3) -> (T,)."""
    return trajectory_min_clearance(robot, trajectories, obstacles)


def trajectory_min_clearance(robot: RobotConfig, trajectories: np.ndarray, obstacles: np.ndarray,
                             valid: np.ndarray | None = None) -> np.ndarray:
    """``pose_clearance(...)`` masked by ``valid`` (T, P) and reduced to its minimum per trajectory
    (T, P, 3) -> (T,), the same values, but the exact footprint distance is computed only where
    it can be the minimum.

    The nearest obstacle centre ``d`` bounds a pose's clearance on both sides: at least
    ``d - radius`` (the bounding circle) and at most ``d - inner_radius`` (the inscribed circle).
    A pose whose lower bound exceeds the smallest upper bound along its trajectory cannot hold
    the trajectory's minimum, so only the others are refined. Along a rollout, that leaves the
    few poses of closest approach.
    """
    poses = np.asarray(trajectories, dtype=np.float64)
    lead = poses.shape[:-1]
    rows = int(np.prod(lead[:-1])) if len(lead) > 1 else 1
    flat = poses.reshape(rows, -1, 3)
    mask = np.ones(flat.shape[:2], dtype=bool) if valid is None else np.asarray(valid, dtype=bool).reshape(flat.shape[:2])
    obs = np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
    out_shape = lead[:-1]
    if obs.shape[0] == 0 or flat.shape[1] == 0:
        return np.full(out_shape, np.inf)
    tree = _kdtree(obs) if flat.shape[0] * flat.shape[1] * obs.shape[0] >= KDTREE_PAIRS else None
    if tree is None:
        clear = pose_clearance(robot, flat, obs)
        return np.where(mask, clear, np.inf).min(axis=-1).reshape(out_shape)
    centre, _ = tree.query(flat[..., :2].reshape(-1, 2), k=1)
    centre = centre.reshape(flat.shape[:2])
    if robot.geometry_type in _ROUND:  # the bounding circle is the footprint: exact already
        return np.where(mask, centre - robot.radius, np.inf).min(axis=-1).reshape(out_shape)
    lower = np.where(mask, centre - robot.radius, np.inf)
    upper = np.where(mask, centre - robot.inner_radius, np.inf)
    # First the pose of each trajectory with the smallest upper bound: its exact distance is a
    # tighter bound than any upper one, then the poses whose lower bound still undercuts it.
    exact = np.full(flat.shape[:2], np.inf)
    judged = np.nonzero(np.isfinite(upper.min(axis=1)))[0]
    first = (judged, upper[judged].argmin(axis=1))
    if judged.size:
        exact[first] = _clearance_kdtree(robot, flat[first], obs, tree)
    candidate = mask & (lower <= exact.min(axis=1, keepdims=True) + 1e-9)
    candidate[first] = False
    where = np.nonzero(candidate)
    if where[0].size:
        exact[where] = _clearance_kdtree(robot, flat[where], obs, tree)
    return exact.min(axis=-1).reshape(out_shape)
