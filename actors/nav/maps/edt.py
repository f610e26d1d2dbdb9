"""Exact Euclidean distance transform in numpy (no scipy).

Felzenszwalb & Huttenlocher's separable algorithm: a 1D squared-distance transform along
every column, then along every row of the result. Each 1D pass is the lower envelope of the
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
    # Read the envelope back: for position q, the parabola whose interval [z_j, z_{j+1}) holds q.
    out = np.full((n_lines, n), np.inf)
    has = k >= 0
    if not has.any():
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
    f = np.where(mask.astype(bool), 0.0, np.inf)
    # Columns first (transpose so the pass runs along the last axis), then rows.
    cols = squared_distance_transform_1d(f.T).T
    sq = squared_distance_transform_1d(cols)
    return np.sqrt(sq) * float(sampling)
