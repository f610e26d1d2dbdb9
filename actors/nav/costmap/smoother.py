"""Nav2's simple smoother, collision-checked against a costmap.

Each sweep moves every inner point by ``w_data * (reference - x) + w_smooth * (prev + next - 2 x)``
until the total move of a sweep is below ``tolerance`` or ``max_its`` sweeps ran; with
``do_refinement`` the result is smoothed again ``refinement_num`` times (each time pulled
towards the previous result). The ends never move. Sweeps update all points at once (numpy),
where Nav2 updates them in order; both converge to the same fixed point.

Collision: after each sweep, a point whose cost is inscribed (253) or lethal (254) goes back to
its original (planned) position and stays there, so the smoothed path never enters cost the
planner's path did not. Unknown cells (255) are not collisions, as in Nav2.
"""
from __future__ import annotations

import numpy as np

from .config import SmootherConfig
from .costs import INSCRIBED_INFLATED_OBSTACLE, NO_INFORMATION
from .grid import Costmap2D

__all__ = ["smooth_path"]


def _colliding(costmap: Costmap2D | None, xy: np.ndarray) -> np.ndarray:
    if costmap is None:
        return np.zeros(len(xy), dtype=bool)
    cost = costmap.cost_at(xy)
    return (cost >= INSCRIBED_INFLATED_OBSTACLE) & (cost != NO_INFORMATION)


def smooth_path(path: np.ndarray, config: SmootherConfig, costmap: Costmap2D | None = None) -> np.ndarray:
    """Smoothed copy of ``path`` (N, 2 or 3: x, y[, yaw]); headings are recomputed along it
    and the last pose keeps its heading."""
    p = np.asarray(path, dtype=float)
    if p.ndim != 2 or p.shape[1] < 2 or not np.all(np.isfinite(p)):
        raise ValueError(f"smooth_path: expected an (N, 2|3) array of finite poses, got shape {p.shape}")
    if len(p) < 3:
        return p.copy()
    original = p[:, :2].copy()
    fixed = np.zeros(len(p), dtype=bool)
    fixed[[0, -1]] = True
    fixed |= _colliding(costmap, original)  # already in cost the planner accepted: leave as planned
    x = original.copy()
    runs = 1 + (config.refinement_num if config.do_refinement else 0)
    for _ in range(runs):
        reference = x.copy()
        for _ in range(config.max_its):
            before = x.copy()
            inner = x[1:-1]
            moved = inner + config.w_data * (reference[1:-1] - inner) + config.w_smooth * (x[2:] + x[:-2] - 2.0 * inner)
            x[1:-1] = np.where(fixed[1:-1, None], inner, moved)
            hit = _colliding(costmap, x) & ~fixed
            if hit.any():
                x[hit] = original[hit]
                fixed |= hit
            if float(np.abs(x - before).sum()) < config.tolerance:
                break
    out = np.zeros((len(p), 3))
    out[:, :2] = x
    out[:, 2] = np.arctan2(np.gradient(x[:, 1]), np.gradient(x[:, 0]))
    if p.shape[1] > 2:
        out[-1, 2] = p[-1, 2]
    return out
