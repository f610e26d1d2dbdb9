"""Trajectory error metrics, with the formulas of the ``evo`` package (Grupp, 2017).

- **ATE** (absolute trajectory error): the estimate is first aligned to the reference by the
  rigid SE(2) transform that minimises the squared position error (Umeyama without scale);
  ATE RMSE is the RMS of the remaining position errors.
- **RPE over d metres** (relative pose error, evo's ``--delta d --delta_unit m``): for every
  pose i, j is the first pose at least ``d`` metres of reference travel later; the error is the
  translation of ``(ref_i^-1 ref_j)^-1 (est_i^-1 est_j)``; RPE RMSE is their RMS. It needs
  no alignment.
"""
from __future__ import annotations

import numpy as np

from emos.geometry import wrap_angle

__all__ = ["align_se2", "ate_rmse", "rpe_rmse"]


def align_se2(est: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """``est`` (N, 3) moved by the rigid transform that best fits its positions to ``ref``'s."""
    est, ref = np.asarray(est, dtype=np.float64), np.asarray(ref, dtype=np.float64)
    if est.shape != ref.shape or est.ndim != 2 or est.shape[1] != 3:
        raise ValueError(f"align_se2: expected two (N, 3) arrays of equal shape, got {est.shape} and {ref.shape}")
    me, mr = est[:, :2].mean(axis=0), ref[:, :2].mean(axis=0)
    h = (est[:, :2] - me).T @ (ref[:, :2] - mr)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    rot = vt.T @ np.diag([1.0, d]) @ u.T
    t = mr - rot @ me
    out = est.copy()
    out[:, :2] = est[:, :2] @ rot.T + t
    out[:, 2] = wrap_angle(est[:, 2] + np.arctan2(rot[1, 0], rot[0, 0]))
    return out


def ate_rmse(est: np.ndarray, ref: np.ndarray) -> float:
    al = align_se2(est, ref)
    return float(np.sqrt(np.mean(np.sum((al[:, :2] - np.asarray(ref)[:, :2]) ** 2, axis=1))))


def _rel(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[:, 2] - a[:, 2])])


def rpe_rmse(est: np.ndarray, ref: np.ndarray, delta_m: float) -> float:
    """RMS translation error of the relative motion over ``delta_m`` metres of reference travel
    (NaN when the trajectory is shorter)."""
    est, ref = np.asarray(est, dtype=np.float64), np.asarray(ref, dtype=np.float64)
    travel = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(ref[:, :2], axis=0).T))])
    j = np.searchsorted(travel, travel + delta_m)
    i = np.flatnonzero(j < len(ref))
    if not len(i):
        return float("nan")
    j = j[i]
    dr, de = _rel(ref[i], ref[j]), _rel(est[i], est[j])
    # The error pose is dr^-1 de; its translation is de's, less dr's, in dr's frame.
    c, s = np.cos(dr[:, 2]), np.sin(dr[:, 2])
    ex, ey = de[:, 0] - dr[:, 0], de[:, 1] - dr[:, 1]
    tx, ty = c * ex + s * ey, -s * ex + c * ey
    return float(np.sqrt(np.mean(tx * tx + ty * ty)))
