"""Exact Euclidean distance transform in numpy (no scipy).

Felzenszwalb & Huttenlocher's separable algorithm: a 1D squared-distance transform along
every column, then along every row of the result. For a binary input the column pass is just
the distance to the nearest feature above or below (two running-max scans); the row pass needs
the general lower-envelope transform. Each 1D pass is the lower envelope of the
parabolas ``(q - p)^2 + f(p)``. Instead of one Python loop per line, every line of the grid is
processed at once: the loop runs over the positions along the line, and each step updates all
lines' envelopes with masked numpy operations. The Python loop is therefore O(width + pops),
independent of the number of lines.
"""
from __future__ import annotations

import numpy as np

__all__ = ["squared_distance_transform_1d", "euclidean_distance_transform"]


def squared_distance_transform_1d(f: np.ndarray) -> np.ndarray:
    """1D squared distance transform along the last axis of a 2D array.

    ``f`` holds the sampled function (0 at feature points, ``inf`` elsewhere, or any
    non-negative values for the second pass). Returns ``d[r, q] = min_p (q - p)^2 + f[r, p]``;
    a line without any finite value stays ``inf``.
    """
    f = np.asarray(f, dtype=np.float64)
    if f.ndim != 2:
        raise ValueError(f"squared_distance_transform_1d: expected a 2D array, got shape {f.shape}")
    n_lines, n = f.shape
    if n == 0 or n_lines == 0:
        return f.copy()
    rows = np.arange(n_lines)
    # Envelope per line: parabola vertices v[:, :k+1], boundaries z[:, :k+2]; k = -1 when empty.
    v = np.zeros((n_lines, n), dtype=np.int64)
    z = np.full((n_lines, n + 1), np.inf)
    k = np.full(n_lines, -1, dtype=np.int64)
    finite = np.isfinite(f)
    for q in range(n):
        fq = f[:, q]
        active = finite[:, q]
        if not active.any():
            continue
        first = active & (k < 0)
        if first.any():
            r = rows[first]
            k[r] = 0
            v[r, 0] = q
            z[r, 0] = -np.inf
            z[r, 1] = np.inf
        cand = rows[active & ~first]
        if cand.size == 0:
            continue
        fq_c = fq[cand] + q * q
        # Pop envelope parabolas hidden by the new one; lines pop independently, so iterate
        # only over the lines that still pop.
        todo = cand
        todo_fq = fq_c
        s_final = np.empty(n_lines)
        while todo.size:
            kv = k[todo]
            vk = v[todo, kv]
            s = (todo_fq - (f[todo, vk] + vk * vk)) / (2.0 * (q - vk))
            pop = s <= z[todo, kv]
            done = ~pop
            s_final[todo[done]] = s[done]
            k[todo[pop]] -= 1
            todo = todo[pop]
            todo_fq = todo_fq[pop]
        k[cand] += 1
        kc = k[cand]
        v[cand, kc] = q
        z[cand, kc] = s_final[cand]
        z[cand, kc + 1] = np.inf
    # Read the envelope back: position q belongs to parabola j where z[j] <= q < z[j+1]
    # (ties go to the lower j, as in the original algorithm). One global searchsorted does it
    # for every line: boundaries are offset by line so they form one sorted array.
    out = np.full((n_lines, n), np.inf)
    has = k >= 0
    if not has.any():
        return out
    r = rows[has]
    kk = k[r]
    span = float(n + 3)
    # Inner boundaries z[1..k] of each line, clipped into [-1, n+1] so offsets keep them apart.
    width = int(kk.max())
    if width > 0:
        inner = np.clip(z[r, 1:width + 1], -1.0, n + 1.0)
        valid = np.arange(1, width + 1)[None, :] <= kk[:, None]
        keys = (inner + (np.arange(r.size)[:, None] * span))[valid]
    else:
        keys = np.zeros(0)
    queries = np.arange(n)[None, :] + (np.arange(r.size)[:, None] * span)
    # Number of inner boundaries < q within the line = index of the parabola.
    before_line = np.r_[0, np.cumsum(kk)[:-1]]
    j = np.searchsorted(keys, queries.ravel(), side="left").reshape(r.size, n) - before_line[:, None]
    vj = np.take_along_axis(v[r], j, axis=1)
    q = np.arange(n)[None, :]
    out[r] = (q - vj) ** 2 + np.take_along_axis(f[r], vj, axis=1)
    return out
    r = rows[has]
    j = np.zeros(r.size, dtype=np.int64)
    zz = z[r]
    vv = v[r]
    ff = f[r]
    ridx = np.arange(r.size)
    for q in range(n):
        # Boundaries only increase, so advancing j monotonically is enough (amortised O(n)).
        while True:
            adv = zz[ridx, j + 1] < q
            if not adv.any():
                break
            j = j + adv
        vj = vv[ridx, j]
        out[r, q] = (q - vj) ** 2 + ff[ridx, vj]
    return out


def _binary_column_distance_sq(mask: np.ndarray) -> np.ndarray:
    """Squared distance from each cell to the nearest True cell in the same column (inf if none)."""
    h = mask.shape[0]
    idx = np.arange(h, dtype=np.float64)[:, None]
    last = np.where(mask, idx, -np.inf)
    np.maximum.accumulate(last, axis=0, out=last)
    nxt = np.where(mask, idx, np.inf)[::-1]
    np.minimum.accumulate(nxt, axis=0, out=nxt)
    nxt = nxt[::-1]
    d = np.minimum(idx - last, nxt - idx)
    return d * d


def euclidean_distance_transform(feature_mask: np.ndarray, sampling: float = 1.0) -> np.ndarray:
    """Exact Euclidean distance from every cell centre to the nearest ``True`` cell centre.

    ``feature_mask`` is a 2D boolean array (e.g. occupied cells). Feature cells get 0; a grid
    without any feature gets ``inf`` everywhere. ``sampling`` scales the result (cell size in
    metres gives metres).
    """
    mask = np.asarray(feature_mask)
    if mask.ndim != 2:
        raise ValueError(f"euclidean_distance_transform: expected a 2D mask, got shape {mask.shape}")
    if not (np.isfinite(sampling) and sampling > 0):
        raise ValueError(f"euclidean_distance_transform: sampling must be > 0, got {sampling!r}")
    # Pass 1 along columns needs no envelope for a binary input: it is the squared distance to
    # the nearest feature above or below, found with two running-max scans (no Python loop).
    cols = _binary_column_distance_sq(mask.astype(bool))
    # Pass 2 along rows: the lower envelope of the column distances.
    sq = squared_distance_transform_1d(cols)
    return np.sqrt(sq) * float(sampling)
