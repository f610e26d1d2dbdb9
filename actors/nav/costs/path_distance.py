"""Distance from many points to a reference polyline, without a dense points x path matrix.

A dense (points x path points) distance matrix for 5,001 x 1,000 trajectory points against a
1,000-point path is 5e9 entries: far too much memory traffic. Instead we precompute, once per
path, a *nearest-segment field* on a grid covering the query area:

1. the path is densified and its samples mark seed cells tagged with their segment index;
2. an exact separable Euclidean distance transform (column pass by running min/max, row pass
   as a small (W x W) min per row, chunked) gives, for every cell, the nearest seed and thus
   the nearest path segment;
3. a query looks up its cell and computes the *exact* distance to that segment and, where
   the projection falls off one of its ends, to the neighbouring segment on that side.

Cost: O(W^2 H) once for the field plus O(points) per query, in float32 and cache-sized chunks.
The result is the exact distance to one or two candidate segments of the simplified path;
it equals the true distance whenever the nearest segment is among them; on
smooth paths the measured error is below 1 mm for most points and a few mm near the path,
and far from the path (where the nearest point is ill-conditioned) it is bounded by about one
grid cell.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

__all__ = ["polyline_distance_exact", "simplify_polyline", "PathDistanceField"]


def _segments(path: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    p = np.asarray(path, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] < 2 or p.shape[0] < 1:
        raise ValueError(f"reference path: expected an (R, 2+) array of points, got shape {p.shape}")
    p = p[:, :2]
    if p.shape[0] == 1:
        p = np.vstack([p, p])
    a = p[:-1]
    d = p[1:] - a
    len2 = np.einsum("ij,ij->i", d, d)
    inv = np.where(len2 > 0, 1.0 / np.where(len2 > 0, len2, 1.0), 0.0)
    return a, d, inv


def _segments_input(path: np.ndarray) -> np.ndarray:
    p = np.asarray(path, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] < 2 or p.shape[0] < 1:
        raise ValueError(f"reference path: expected an (R, 2+) array of points, got shape {p.shape}")
    return p[:, :2]


def polyline_distance_exact(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Exact distance of points (..., 2) to the polyline ``path`` (R, 2); O(points x R).

    Loops over segments (vectorized over points), so it is cheap for short or simplified
    paths; the reference the distance field is validated against.
    """
    a, d, inv = _segments(path)
    pts = np.asarray(points, dtype=np.float64)
    px = pts[..., 0]
    py = pts[..., 1]
    best = np.full(px.shape, np.inf)
    for k in range(a.shape[0]):
        wx = px - a[k, 0]
        wy = py - a[k, 1]
        t = np.clip((wx * d[k, 0] + wy * d[k, 1]) * inv[k], 0.0, 1.0)
        wx -= t * d[k, 0]
        wy -= t * d[k, 1]
        np.minimum(best, wx * wx + wy * wy, out=best)
    return np.sqrt(best)


def simplify_polyline(path: np.ndarray, tolerance: float) -> np.ndarray:
    """Ramer-Douglas-Peucker: drop vertices closer than ``tolerance`` to the kept chord.

    Distances to the simplified polyline differ from the original by at most ``tolerance``.
    Each step is vectorized over the vertices of one span; steps ~ number of kept vertices.
    """
    p = np.asarray(path, dtype=np.float64)[:, :2]
    n = p.shape[0]
    if n <= 2:
        return p
    keep = np.zeros(n, dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        a, b = p[i], p[j]
        mid = p[i + 1:j]
        ab = b - a
        L2 = float(ab @ ab)
        if L2 == 0.0:
            dist = np.hypot(mid[:, 0] - a[0], mid[:, 1] - a[1])
        else:
            t = np.clip(((mid - a) @ ab) / L2, 0.0, 1.0)
            e = mid - (a + t[:, None] * ab)
            dist = np.hypot(e[:, 0], e[:, 1])
        k = int(np.argmax(dist))
        if dist[k] > tolerance:
            m = i + 1 + k
            keep[m] = True
            stack.append((i, m))
            stack.append((m, j))
    return p[keep]


class PathDistanceField:
    """Nearest-segment field of a polyline over a bounding box (see module docstring)."""

    def __init__(self, path: np.ndarray, bounds: tuple[float, float, float, float],
                 resolution: float = 0.05, max_cells: int = 320, tolerance: float = 1e-3) -> None:
        # Dense paths have segments far shorter than a grid cell; checking one segment and its
        # neighbours would then miss the nearest one. Simplifying first (within ``tolerance``)
        # leaves segments long enough for the +-1 neighbourhood to be exact on smooth paths.
        a, d, inv = _segments(simplify_polyline(_segments_input(path), tolerance))
        self.n_segments = a.shape[0]
        # For offsets -1, 0, +1: contiguous arrays (ax, ay, ux, uy, length) of segment k+off
        # indexed by k (u the unit direction), so a query needs plain 1D gathers only.
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        unit = d / np.maximum(length, 1e-12)[:, None]
        seg = [np.ascontiguousarray(v, dtype=np.float32) for v in (a[:, 0], a[:, 1], unit[:, 0], unit[:, 1], length)]
        idx = np.arange(self.n_segments)
        self._neighbours = [
            tuple(np.ascontiguousarray(v[np.clip(idx + off, 0, self.n_segments - 1)]) for v in seg)
            for off in (-1, 0, 1)
        ]
        pts = np.asarray(path, dtype=np.float64)[:, :2]
        xmin = min(bounds[0], pts[:, 0].min())
        ymin = min(bounds[1], pts[:, 1].min())
        xmax = max(bounds[2], pts[:, 0].max())
        ymax = max(bounds[3], pts[:, 1].max())
        # Coarsen the grid rather than let the O(W^2 H) transform explode on a wide area.
        res = max(float(resolution), (xmax - xmin) / max_cells, (ymax - ymin) / max_cells, 1e-6)
        self.resolution = res
        self.origin = np.array([xmin - res, ymin - res])
        self.width = int(np.ceil((xmax - xmin) / res)) + 3
        self.height = int(np.ceil((ymax - ymin) / res)) + 3
        self.segment_of_cell = self._build(a, d, res)

    def _build(self, a: np.ndarray, d: np.ndarray, res: float) -> np.ndarray:
        H, W = self.height, self.width
        # Densify: samples every res/2 along each segment, tagged with their segment index.
        lengths = np.sqrt(np.einsum("ij,ij->i", d, d))
        counts = np.maximum(1, np.ceil(lengths / (0.5 * res)).astype(np.int64)) + 1
        seg_id = np.repeat(np.arange(a.shape[0]), counts)
        starts = np.cumsum(counts) - counts
        frac = (np.arange(seg_id.size) - np.repeat(starts, counts)) / np.repeat(counts - 1, counts)
        samples = a[seg_id] + frac[:, None] * d[seg_id]
        cols = np.clip(((samples[:, 0] - self.origin[0]) / res).astype(np.int64), 0, W - 1)
        rows = np.clip(((samples[:, 1] - self.origin[1]) / res).astype(np.int64), 0, H - 1)
        seed_seg = np.full((H, W), -1, dtype=np.int32)
        seed_seg[rows, cols] = seg_id
        is_seed = seed_seg >= 0
        # Column pass: nearest seed row above/below each cell, by running max/min of row ids.
        r = np.arange(H)[:, None]
        big = 4 * (H + W)
        up = np.maximum.accumulate(np.where(is_seed, r, -big), axis=0)
        down = np.minimum.accumulate(np.where(is_seed, r, big)[::-1], axis=0)[::-1]
        use_up = (r - up) <= (down - r)
        seed_row = np.where(use_up, up, down)
        g = np.abs(seed_row - r).astype(np.float32)  # vertical distance in cells
        seed_row = np.clip(seed_row, 0, H - 1)
        # Row pass: D^2(y, x) = min_x' (x - x')^2 + g(y, x')^2, chunked over rows.
        xs = np.arange(W, dtype=np.float32)
        dx2 = (xs[:, None] - xs[None, :]) ** 2  # (x, x')
        best_col = np.empty((H, W), dtype=np.int64)
        chunk = max(1, (1 << 22) // (W * W))
        for y0 in range(0, H, chunk):
            gy = g[y0:y0 + chunk]  # (c, x')
            cand = dx2[None, :, :] + (gy * gy)[:, None, :]
            best_col[y0:y0 + chunk] = np.argmin(cand, axis=2)
        rows_idx = np.arange(H)[:, None]
        nearest_row = seed_row[rows_idx, best_col]
        seg = seed_seg[nearest_row, best_col]
        # Only an empty seed set leaves -1 behind; the path always seeds at least one cell.
        return np.maximum(seg, 0).astype(np.int32)

    def distance(self, points: np.ndarray, chunk: int = 1 << 16, threads: int | None = None) -> np.ndarray:
        """Distance (float32) of points (..., 2+) to the path; extra columns are ignored.

        Chunks are independent, and numpy releases the GIL inside ufuncs, so with ``threads``
        > 1 (default: up to 2, the cores of the reference machine) chunks run in parallel.
        """
        pts = np.asarray(points)
        lead = pts.shape[:-1]
        # (N, C) view without copying when the input is contiguous, e.g. (T, P, 3) poses.
        flat = pts.reshape(-1, pts.shape[-1])
        out = np.empty(flat.shape[0], dtype=np.float32)
        starts = range(0, flat.shape[0], chunk)
        workers = min(threads if threads is not None else min(2, os.cpu_count() or 1), len(starts))
        if workers > 1:
            with ThreadPoolExecutor(max_workers=workers) as pool:
                list(pool.map(lambda s: self._distance_chunk(flat, out, s, chunk), starts))
        else:
            for s in starts:
                self._distance_chunk(flat, out, s, chunk)
        return out.reshape(lead)

    def _distance_chunk(self, flat: np.ndarray, out: np.ndarray, s: int, chunk: int) -> None:
        ox, oy = np.float32(self.origin[0]), np.float32(self.origin[1])
        inv_res = np.float32(1.0 / self.resolution)
        px = flat[s:s + chunk, 0].astype(np.float32)
        py = flat[s:s + chunk, 1].astype(np.float32)
        ci = np.clip(((px - ox) * inv_res).astype(np.int32), 0, self.width - 1)
        ri = np.clip(((py - oy) * inv_res).astype(np.int32), 0, self.height - 1)
        k = self.segment_of_cell[ri, ci]
        d2, before, after = self._segment_d2(px, py, k, self._neighbours[1])
        # Only where the projection onto segment k was clamped at one of its ends can a
        # neighbouring segment be nearer; checking it just there (about 40 % of points on
        # the benchmark) instead of everywhere saves a third of the work.
        for mask, table in ((before, self._neighbours[0]), (after, self._neighbours[2])):
            sel = np.flatnonzero(mask)
            if sel.size:
                other, _, _ = self._segment_d2(px[sel], py[sel], k[sel], table)
                d2[sel] = np.minimum(d2[sel], other)
        np.maximum(d2, 0.0, out=d2)
        out[s:s + chunk] = np.sqrt(d2)

    @staticmethod
    def _segment_d2(px: np.ndarray, py: np.ndarray, k: np.ndarray, table) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Squared distance to segment ``table[k]``, and masks of projections before/after it.

        With unit direction u and length L: p = w.u, t = clip(p, 0, L), and
        |w - t u|^2 = |w|^2 - t (2 p - t): one fewer gather and multiply than the textbook form.
        """
        ax, ay, ux, uy, length = table
        wx = px - ax[k]
        wy = py - ay[k]
        proj = wx * ux[k]
        proj += wy * uy[k]
        seg_len = length[k]
        before = proj < 0.0
        after = proj > seg_len
        t = np.clip(proj, 0.0, seg_len)
        wx *= wx
        wy *= wy
        wx += wy
        proj *= 2.0
        proj -= t
        proj *= t
        wx -= proj
        return wx, before, after
