"""The likelihood grid a scan is matched against, and its max-pooled tables.

A submap is a :class:`LikelihoodGrid`: cell value = ``exp(-d^2 / (2 sigma^2))`` where ``d`` is the
distance from the cell centre to the nearest scan hit inserted so far (0 beyond ``3.5 sigma``).
Inserting a scan splats a small Gaussian kernel around each hit with ``np.maximum.at``, so
the cost of an insertion is O(hits), never O(grid): the field is the maximum over hits of each
hit's kernel, which is exactly the Gaussian of the nearest-hit distance within the kernel's
reach. The grid grows (re-allocates with a margin) when a hit falls outside it.

:func:`max_tables` gives Olson's multi-resolution lookup tables for branch and bound:
``table_b[i, j] = max(field[i:i + b, j:j + b])``, the best value any of the ``b x b`` finer
offsets of a block can reach, so a block's score is an upper bound of its children's.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["LikelihoodGrid", "max_tables"]


class LikelihoodGrid:
    """A growing float32 likelihood field (see the module docstring). ``origin``: world (x, y)
    of the corner of cell (0, 0); ``data[row, col]``, row along y."""

    def __init__(self, resolution: float = 0.05, sigma: float = 0.05, margin: float = 5.0) -> None:
        if not (resolution > 0 and sigma > 0 and margin >= 0):
            raise ValueError(f"LikelihoodGrid: expected resolution > 0, sigma > 0 and margin >= 0, got "
                             f"{resolution!r}, {sigma!r}, {margin!r}")
        self.resolution = float(resolution)
        self.sigma = float(sigma)
        self.margin = float(margin)
        self.origin = np.zeros(2)
        self.data = np.zeros((0, 0), dtype=np.float32)
        self.hits = 0
        k = int(math.ceil(3.5 * sigma / resolution))
        dy, dx = np.mgrid[-k:k + 1, -k:k + 1]
        self._kernel = np.column_stack([dx.ravel(), dy.ravel()]).astype(np.int64)  # (K, 2) cell offsets
        self._reach = (k + 1) * self.resolution

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.data.shape[0]), int(self.data.shape[1]))

    def _ensure(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Grow the grid so that the world box [lo, hi] is inside it (plus the margin)."""
        h, w = self.data.shape
        if h and w:
            cur_lo = self.origin
            cur_hi = self.origin + np.array([w, h]) * self.resolution
            if np.all(lo >= cur_lo) and np.all(hi <= cur_hi):
                return
            new_lo = np.minimum(cur_lo, lo - self.margin)
            new_hi = np.maximum(cur_hi, hi + self.margin)
        else:
            new_lo, new_hi = lo - self.margin, hi + self.margin
        # Keep the new origin on the old lattice so that old cells keep their place exactly.
        shift = np.floor((self.origin - new_lo) / self.resolution).astype(np.int64) if h and w else np.zeros(2, np.int64)
        origin = self.origin - shift * self.resolution if h and w else new_lo
        size = np.ceil((new_hi - origin) / self.resolution).astype(np.int64)
        data = np.zeros((int(size[1]), int(size[0])), dtype=np.float32)
        if h and w:
            data[shift[1]:shift[1] + h, shift[0]:shift[0] + w] = self.data
        self.data, self.origin = data, origin

    def insert(self, points: np.ndarray) -> None:
        """Add world hit points (N, 2) (finite ones only; the caller filters ranges)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        pts = pts[np.isfinite(pts).all(axis=1)]
        if not len(pts):
            return
        self._ensure(pts.min(axis=0) - self._reach, pts.max(axis=0) + self._reach)
        cell = np.floor((pts - self.origin) / self.resolution).astype(np.int64)
        cells = (cell[:, None, :] + self._kernel[None, :, :]).reshape(-1, 2)
        centres = self.origin + (cells + 0.5) * self.resolution
        d2 = np.sum((centres - np.repeat(pts, len(self._kernel), axis=0)) ** 2, axis=1)
        val = np.exp(-0.5 * d2 / (self.sigma * self.sigma)).astype(np.float32)
        np.maximum.at(self.data, (cells[:, 1], cells[:, 0]), val)
        self.hits += len(pts)

    def crop(self, lo_cell: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        """The (rows, cols) block of the field whose cell (0, 0) is grid cell ``lo_cell``
        (col, row); cells outside the grid read 0."""
        out = np.zeros(shape, dtype=np.float32)
        h, w = self.data.shape
        c0, r0 = int(lo_cell[0]), int(lo_cell[1])
        rs, re = max(r0, 0), min(r0 + shape[0], h)
        cs, ce = max(c0, 0), min(c0 + shape[1], w)
        if rs < re and cs < ce:
            out[rs - r0:re - r0, cs - c0:ce - c0] = self.data[rs:re, cs:ce]
        return out


def _sliding_max(a: np.ndarray, b: int, axis: int) -> np.ndarray:
    """``out[i] = max(a[i:i + b])`` along ``axis`` (zeros past the end), by doubling: log2(b) passes."""
    out = a
    span = 1
    while span < b:
        step = min(span, b - span)
        shifted = np.zeros_like(out)
        if axis == 0:
            shifted[:-step] = out[step:]
        else:
            shifted[:, :-step] = out[:, step:]
        out = np.maximum(out, shifted)
        span += step
    return out


def max_tables(field: np.ndarray, blocks: list[int]) -> dict[int, np.ndarray]:
    """Olson's lookup tables: for each block size ``b``, ``t[i, j] = max(field[i:i+b, j:j+b])``."""
    return {b: field if b == 1 else _sliding_max(_sliding_max(field, b, 0), b, 1) for b in blocks}
