"""Trajectory cost kernels, vectorized over (trajectories x points).

Each kernel returns one normalized cost per trajectory; ``evaluate_costs`` forms the weighted
sum ``J = sum(w_i * C_i)`` and never calls a kernel whose weight is 0.

Definitions (T trajectories, P points, poses (T, P, 2+), velocities (T, P, 3)):

* reference path: mean over points of the distance (m) to the reference polyline;
* goal: distance from the last point to the goal, divided by the reference path length
  (1 m when there is no reference path), so 1.0 means "a whole path length away";
* obstacles: the inverse of the clearance in robot radii, ``r / max(clearance, 0.01 m)``,
  with clearance the smallest distance from any point to any obstacle minus the robot radius
  ``r`` (``r = 1 m`` for a point robot); 0 when there are no obstacles. Measuring in robot
  radii keeps the term commensurate with the others: with plain ``1 / clearance`` a robot
  parks half a metre in front of an obstacle it could pass, its repulsion outweighing the
  progress a short dynamic-window step can make;
* smoothness: mean over steps of ``sum_axis |dv| / (a_max * dt)``: 1.0 per step means
  changing velocity at exactly the acceleration limit on one axis;
* jerk: mean over steps of ``sum_axis |d^2 v| / (a_max * dt)``: the change of that change.
"""
from __future__ import annotations

import attrs
import numpy as np

from .path_distance import PathDistanceField, polyline_distance_exact, simplify_polyline
from .weights import TrajectoryCostsWeights

__all__ = [
    "reference_path_cost",
    "goal_cost",
    "obstacles_cost",
    "min_obstacle_distance",
    "smoothness_cost",
    "jerk_cost",
    "evaluate_costs",
    "CostBreakdown",
]

# Above this many (points x path segments) pairs, the nearest-segment field replaces the
# exact dense computation.
_DENSE_LIMIT = 2_000_000


def _xy(trajectories: np.ndarray) -> np.ndarray:
    t = np.asarray(trajectories)
    if t.ndim != 3 or t.shape[-1] < 2:
        raise ValueError(f"trajectories: expected shape (T, P, 2 or 3), got {t.shape}")
    return t[..., :2]


def _check_path(path: np.ndarray) -> np.ndarray:
    p = np.asarray(path, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] < 2 or p.shape[0] < 1:
        raise ValueError(f"reference_path: expected an (R, 2+) array, got shape {p.shape}")
    return p[:, :2]


def path_length(path: np.ndarray) -> float:
    p = np.asarray(path, dtype=np.float64)[:, :2]
    if p.shape[0] < 2:
        return 0.0
    return float(np.sum(np.hypot(*np.diff(p, axis=0).T)))


def reference_path_cost(trajectories: np.ndarray, reference_path: np.ndarray,
                        field: PathDistanceField | None = None, resolution: float = 0.05) -> np.ndarray:
    """Mean distance (m) of each trajectory's points to the reference path."""
    xy = _xy(trajectories)
    ref = np.asarray(reference_path)
    if field is None:
        # Collinear and nearly collinear points change distances by < 1 mm: drop them.
        ref = simplify_polyline(_check_path(ref), 1e-3)
    if field is None and xy.shape[0] * xy.shape[1] * max(ref.shape[0] - 1, 1) <= _DENSE_LIMIT:
        return polyline_distance_exact(xy, ref).mean(axis=1)
    if field is None:
        bounds = (float(xy[..., 0].min()), float(xy[..., 1].min()),
                  float(xy[..., 0].max()), float(xy[..., 1].max()))
        field = PathDistanceField(ref, bounds, resolution=resolution)
    # Pass the poses themselves (not the x, y slice): a contiguous (T, P, 3) array reshapes
    # without a copy, and the field reads only the first two columns.
    return field.distance(np.asarray(trajectories)).mean(axis=1, dtype=np.float64)


def goal_cost(trajectories: np.ndarray, goal: np.ndarray, normalizer: float = 1.0) -> np.ndarray:
    """Distance from each trajectory's end to ``goal`` over ``normalizer`` (> 0)."""
    xy = _xy(trajectories)
    g = np.asarray(goal, dtype=np.float64).reshape(-1)[:2]
    end = xy[:, -1, :]
    return np.hypot(end[:, 0] - g[0], end[:, 1] - g[1]) / max(float(normalizer), 1e-9)


def min_obstacle_distance(trajectories: np.ndarray, obstacles: np.ndarray,
                          chunk_pairs: int = 1 << 20) -> np.ndarray:
    """Smallest centre-to-obstacle distance per trajectory (inf without obstacles)."""
    xy = _xy(trajectories).astype(np.float32)
    obs = np.asarray(obstacles, dtype=np.float32).reshape(-1, 2)
    T, P, _ = xy.shape
    out = np.full(T, np.inf, dtype=np.float64)
    if obs.shape[0] == 0:
        return out
    rows = max(1, chunk_pairs // max(P * obs.shape[0], 1))
    for s in range(0, T, rows):
        q = xy[s:s + rows].reshape(-1, 2)
        dx = q[:, 0:1] - obs[None, :, 0]
        dy = q[:, 1:2] - obs[None, :, 1]
        d2 = (dx * dx + dy * dy).min(axis=1)
        out[s:s + rows] = np.sqrt(d2.reshape(-1, P).min(axis=1))
    return out


def obstacles_cost(trajectories: np.ndarray | None, obstacles: np.ndarray | None,
                   robot_radius: float = 0.0, min_distance: np.ndarray | None = None) -> np.ndarray:
    """``r / max(clearance, 0.01)`` per trajectory (see module docstring); ``min_distance``
    (centre to nearest obstacle) may be precomputed."""
    if min_distance is None:
        if trajectories is None:
            raise ValueError("obstacles_cost: give trajectories or a precomputed min_distance")
        if obstacles is None or np.asarray(obstacles).size == 0:
            return np.zeros(_xy(trajectories).shape[0])
        min_distance = min_obstacle_distance(trajectories, obstacles)
    clearance = np.asarray(min_distance, dtype=np.float64) - robot_radius
    scale = robot_radius if robot_radius > 0 else 1.0
    cost = scale / np.maximum(clearance, 0.01)
    return np.where(np.isinf(min_distance), 0.0, cost)


def _acc_scale(acc_limits: np.ndarray | None, dt: float) -> np.ndarray:
    acc = np.ones(3) if acc_limits is None else np.asarray(acc_limits, dtype=np.float64).reshape(3)
    if np.any(acc <= 0) or dt <= 0:
        raise ValueError(f"smoothness/jerk: expected acc limits > 0 and dt > 0, got {acc}, {dt}")
    return (1.0 / (acc * dt)).astype(np.float32)


def _with_initial(velocities: np.ndarray, initial: np.ndarray | None) -> np.ndarray:
    v = np.asarray(velocities)
    if v.ndim != 3 or v.shape[-1] != 3:
        raise ValueError(f"velocities: expected shape (T, P, 3), got {v.shape}")
    if initial is None:
        return v
    init = np.broadcast_to(np.asarray(initial, dtype=v.dtype).reshape(1, 1, 3), (v.shape[0], 1, 3))
    return np.concatenate([init, v], axis=1)


def _per_step_change(v: np.ndarray, order: int, scale: np.ndarray, rows: int = 128) -> np.ndarray:
    """Mean over steps of sum_axis |d^order v| * scale, chunked over trajectories.

    Chunks of ``rows`` trajectories keep the float32 temporaries in cache: on the 5,001 x
    1,000 benchmark this is several times faster than one pass over the whole array.
    """
    T, P, _ = v.shape
    out = np.empty(T)
    for s in range(0, T, rows):
        block = np.asarray(v[s:s + rows], dtype=np.float32)
        d = block[:, 1:] - block[:, :-1]
        if order == 2:
            d = d[:, 1:] - d[:, :-1]
        np.abs(d, out=d)
        out[s:s + rows] = (d @ scale).mean(axis=1, dtype=np.float64)
    return out


def smoothness_cost(velocities: np.ndarray, dt: float, acc_limits: np.ndarray | None = None,
                    initial_velocity: np.ndarray | None = None) -> np.ndarray:
    """Mean normalized velocity change per step (see module docstring)."""
    v = _with_initial(velocities, initial_velocity)
    if v.shape[1] < 2:
        return np.zeros(v.shape[0])
    return _per_step_change(v, 1, _acc_scale(acc_limits, dt))


def jerk_cost(velocities: np.ndarray, dt: float, acc_limits: np.ndarray | None = None,
              initial_velocity: np.ndarray | None = None) -> np.ndarray:
    """Mean normalized change of the velocity change per step (see module docstring)."""
    v = _with_initial(velocities, initial_velocity)
    if v.shape[1] < 3:
        return np.zeros(v.shape[0])
    return _per_step_change(v, 2, _acc_scale(acc_limits, dt))


@attrs.define
class CostBreakdown:
    """Total cost per trajectory and the weighted terms that were actually computed."""

    total: np.ndarray
    terms: dict[str, np.ndarray]


def evaluate_costs(
    weights: TrajectoryCostsWeights,
    trajectories: np.ndarray,
    velocities: np.ndarray | None = None,
    *,
    reference_path: np.ndarray | None = None,
    goal: np.ndarray | None = None,
    obstacles: np.ndarray | None = None,
    robot_radius: float = 0.0,
    dt: float = 0.1,
    acc_limits: np.ndarray | None = None,
    initial_velocity: np.ndarray | None = None,
    obstacle_min_distance: np.ndarray | None = None,
    path_field: PathDistanceField | None = None,
    goal_normalizer: float | None = None,
) -> CostBreakdown:
    """Weighted total cost per trajectory. Kernels with weight 0 are not run at all.

    ``goal_normalizer`` (m) overrides the goal term's default divisor, the reference path
    length (a sampling controller may prefer the distance it can cover in its horizon).
    """
    T = _xy(trajectories).shape[0]
    total = np.zeros(T)
    terms: dict[str, np.ndarray] = {}
    ref_len = path_length(reference_path) if reference_path is not None else 0.0
    if goal_normalizer is not None:
        if not goal_normalizer > 0:
            raise ValueError(f"goal_normalizer: expected > 0 m, got {goal_normalizer!r}")
        ref_len = float(goal_normalizer)
    if weights.reference_path_distance_weight > 0 and reference_path is not None:
        terms["reference_path"] = reference_path_cost(trajectories, reference_path, field=path_field)
    if weights.goal_distance_weight > 0 and goal is not None:
        terms["goal"] = goal_cost(trajectories, goal, ref_len if ref_len > 0 else 1.0)
    if weights.obstacles_distance_weight > 0 and (obstacles is not None or obstacle_min_distance is not None):
        terms["obstacles"] = obstacles_cost(trajectories, obstacles, robot_radius, obstacle_min_distance)
    if weights.smoothness_weight > 0 and velocities is not None:
        terms["smoothness"] = smoothness_cost(velocities, dt, acc_limits, initial_velocity)
    if weights.jerk_weight > 0 and velocities is not None:
        terms["jerk"] = jerk_cost(velocities, dt, acc_limits, initial_velocity)
    w = {
        "reference_path": weights.reference_path_distance_weight,
        "goal": weights.goal_distance_weight,
        "obstacles": weights.obstacles_distance_weight,
        "smoothness": weights.smoothness_weight,
        "jerk": weights.jerk_weight,
    }
    for name, value in terms.items():
        total += w[name] * value
    return CostBreakdown(total=total, terms=terms)
