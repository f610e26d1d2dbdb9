"""Point-to-line ICP between two scans (Censi, "An ICP variant using a point-to-line metric",
ICRA 2008): the scan-to-scan constraint of the pose graph's refinement (``slam.GraphSlam``).

Why scan to scan: a scan is the one rigid thing a 2D lidar gives (180 to 361 beams taken in a
few milliseconds); a submap is as rigid only as the front-end poses of the 20 scans inside it,
and a factor measured against a submap freezes that distortion into the graph. A constraint
between two scans carries no one else's pose, so a graph of them (Lu and Milios, "Globally
consistent range scan alignment", 1997; Karto / slam_toolbox's scan-to-scan edges) spreads
each scan's error over its neighbours instead of stacking it.

- **Reference scan** (:class:`IcpScan`): its hits with a normal each, from the principal axis
  of the hit and its neighbours within ``normal_radius``; hits whose neighbourhood is not
  line-like (a corner, a lone return) get no normal and are not matched against.
- **Match** (:func:`icp_match`): the other scan's hits go through the current relative pose to
  the nearest reference hit (a k-d tree); a pair farther than the gate is dropped; Gauss-Newton
  on the point-to-line distances under Huber weights, the gate shrinking from ``gate_start`` to
  ``gate_end``. The result's information is ``J^T W J / s^2`` (``s``: the residual spread, with
  a floor): along a corridor the normals all point across it and the information along it is
  near zero, as it should be.

Cost: O(n log n) for n hits per pair, a few iterations; bounded by the beam count.
"""
from __future__ import annotations

import math

import attrs
import numpy as np
from scipy.spatial import cKDTree

__all__ = ["IcpResult", "IcpScan", "icp_match"]


@attrs.define(frozen=True, eq=False)
class IcpScan:
    """A reference scan: ``points`` (M, 2, its own frame), unit ``normals`` (M, 2) of the hits
    that have one, and the k-d tree over ``points``."""

    points: np.ndarray
    normals: np.ndarray
    tree: cKDTree
    all_points: np.ndarray

    @classmethod
    def build(cls, points: np.ndarray, normal_radius: float = 0.25, neighbours: int = 6,
              max_flatness: float = 0.3) -> IcpScan:
        """``points`` (N, 2) finite hits. A hit's normal: the minor axis of it and its
        ``neighbours`` nearest hits within ``normal_radius`` (at least 3 of them), kept when the
        spread across that axis is at most ``max_flatness`` times the spread along it."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        empty = np.zeros((0, 2))
        if len(pts) < 3:
            return cls(points=empty, normals=empty, tree=cKDTree(np.full((1, 2), 1e9)), all_points=pts)
        tree = cKDTree(pts)
        k = min(neighbours + 1, len(pts))
        dist, idx = tree.query(pts, k=k, distance_upper_bound=normal_radius)
        ok = np.isfinite(dist)
        cnt = ok.sum(axis=1)
        idx = np.where(ok, idx, 0)
        q = pts[idx]  # (N, k, 2)
        w = ok[..., None]
        mean = (q * w).sum(axis=1) / np.maximum(cnt, 1)[:, None]
        d = (q - mean[:, None, :]) * w
        sxx, syy, sxy = (d[..., 0] ** 2).sum(1), (d[..., 1] ** 2).sum(1), (d[..., 0] * d[..., 1]).sum(1)
        # Closed-form eigen-decomposition of [[sxx, sxy], [sxy, syy]].
        tr, det = sxx + syy, sxx * syy - sxy * sxy
        disc = np.sqrt(np.maximum(tr * tr / 4 - det, 0.0))
        lo, hi = tr / 2 - disc, tr / 2 + disc
        ang = 0.5 * np.arctan2(2 * sxy, sxx - syy)  # major axis
        normals = np.column_stack([-np.sin(ang), np.cos(ang)])
        keep = (cnt >= 3) & (hi > 0) & (lo <= max_flatness * max_flatness * hi)
        if not keep.any():
            return cls(points=empty, normals=empty, tree=cKDTree(np.full((1, 2), 1e9)), all_points=pts)
        sel = pts[keep]
        return cls(points=sel, normals=normals[keep], tree=cKDTree(sel), all_points=pts)


@attrs.define(frozen=True, eq=False)
class IcpResult:
    """``pose``: the source scan's pose in the reference scan's frame; ``information`` (3x3,
    x y theta in the *reference* frame's axes); ``pairs``: matched hits; ``overlap``: their
    share of the source's hits; ``rms``: point-to-line RMS (m)."""

    pose: np.ndarray
    information: np.ndarray
    pairs: int
    overlap: float
    rms: float


def _transform(pose: np.ndarray, pts: np.ndarray) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.column_stack([c * pts[:, 0] - s * pts[:, 1] + pose[0], s * pts[:, 0] + c * pts[:, 1] + pose[1]])


def icp_match(ref: IcpScan, source: np.ndarray, guess: np.ndarray, *, gate_start: float = 0.3,
              gate_end: float = 0.1, iterations: int = 12, huber: float = 0.03, sd_floor: float = 0.01,
              min_pairs: int = 30, prior_sd: tuple[float, float] | None = None) -> IcpResult | None:
    """The pose of ``source`` (N, 2, its own frame) in ``ref``'s frame, from ``guess``; None
    when fewer than ``min_pairs`` hits find a line or the system is singular. ``prior_sd``
    (m, rad): a Gaussian prior towards ``guess``, weighted as that many pairs of ``huber``
    spread would be: along a corridor, where the lines say nothing, the pose then stays at the
    guess instead of sliding."""
    src = np.asarray(source, dtype=np.float64).reshape(-1, 2)
    if len(ref.points) < min_pairs or len(src) < min_pairs:
        return None
    pose = np.asarray(guess, dtype=np.float64).reshape(3).copy()
    start = pose.copy()
    gates = np.geomspace(gate_start, gate_end, max(iterations // 2, 1))
    info = np.zeros((3, 3))
    n = 0
    rms = float("inf")
    for it in range(iterations):
        gate = float(gates[min(it, len(gates) - 1)])
        q = _transform(pose, src)
        dist, found = ref.tree.query(q, distance_upper_bound=gate)
        ok = np.isfinite(dist)
        idx = np.asarray(found, dtype=np.int64)
        n = int(np.count_nonzero(ok))
        if n < min_pairs:
            return None
        qn, nrm, p = q[ok], ref.normals[idx[ok]], ref.points[idx[ok]]
        r = np.sum(nrm * (qn - p), axis=1)
        # d(q)/d(theta) = R'(theta) s = perpendicular of (q - t)
        rel = qn - pose[:2]
        jt = nrm[:, 0] * -rel[:, 1] + nrm[:, 1] * rel[:, 0]
        jac = np.column_stack([nrm[:, 0], nrm[:, 1], jt])
        a = np.abs(r)
        w = np.where(a <= huber, 1.0, huber / np.maximum(a, 1e-12))
        h = (jac * w[:, None]).T @ jac
        g = (jac * w[:, None]).T @ r
        if prior_sd is not None:
            prior = np.diag([1.0 / prior_sd[0] ** 2, 1.0 / prior_sd[0] ** 2, 1.0 / prior_sd[1] ** 2]) * huber * huber * n
            h = h + prior
            g = g + prior @ (pose - start)
        try:
            delta = -np.linalg.solve(h + np.eye(3) * 1e-9, g)
        except np.linalg.LinAlgError:
            return None
        pose = pose + delta
        rms = float(math.sqrt(np.sum(w * r * r) / max(np.sum(w), 1e-12)))
        info = h
        if it >= len(gates) and abs(delta[0]) < 1e-4 and abs(delta[1]) < 1e-4 and abs(delta[2]) < 1e-5:
            break
    s2 = max(rms, sd_floor) ** 2
    return IcpResult(pose=pose, information=info / s2, pairs=n, overlap=n / len(src), rms=rms)
