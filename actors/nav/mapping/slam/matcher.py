"""Correlative scan matching (Olson, "Real-time correlative scan matching", ICRA 2009), exact
branch and bound over (x, y, theta), then a sub-cell polish and a covariance from the response.

1. **Search.** Candidate poses are a lattice around a guess: translations in whole cells of the
   likelihood grid within ``+-window_xy``, headings in steps small enough that the farthest
   used hit moves about one cell. A candidate's score is the mean likelihood of the scan's
   hits (0..1; hits off the map count 0, so a scan that overlaps little cannot score high).
   Branch and bound over translation blocks of 16, 4 and 1 cells with the max-pooled tables of
   :func:`grid.max_tables` finds the best lattice pose exactly (every block's score bounds its
   children's), visiting a small part of the lattice. All scoring is vectorised over hits and
   candidates. An optional prior (``prior_weight`` > 0) multiplies a score by a Gaussian of the
   distance to the guess, so that in a featureless corridor the odometry decides along it; its
   bound over a block uses the block's nearest point to the guess, so the search stays exact.
2. **Polish.** Levenberg-Marquardt on the bilinear-interpolated field moves the pose off the
   lattice (the grid is 5 cm; the trajectory must be better than that).
3. **Covariance.** The scores of the lattice around the best pose (+-``cov_cells`` cells,
   +-``cov_steps`` heading steps) become weights ``exp((s - s_best) / cov_tau)``; their weighted
   spread is the match's covariance (Olson, section IV). In a corridor the response is flat
   along it and the covariance says so: the pose graph then trusts the odometry there, and a
   loop closure with an ambiguous match is refused (:attr:`MatchResult.ambiguous`).

4. **Curvature covariance** (:attr:`MatchResult.hessian_covariance`): ``(N H)^-1`` with ``H``
   the curvature of the mean score at the polished pose (central differences, two cells and two
   heading steps) and ``N`` the hit count: the covariance the hits would give if they were
   independent measurements with the field's sigma (``_hessian_covariance``). Along a corridor
   the score is flat and only the window bounds it. Independent of the lattice and of a
   temperature; hits on one wall are not independent and a submap is not rigid, so its scale is
   too small by a roughly constant factor, which the SLAM calibrates
   (``SlamParams.hessian_cov_scale``). (The Gauss-Newton ``s2 (J^T J)^-1`` of the polish was
   tried first and is wrong here: at a good fit every hit sits on the crest of the field, where
   its gradient is zero, so ``J^T J`` has no information *across* a wall and the corridor came
   out backwards.)

Per-call cost is bounded by the window and the hit count (the crop of the grid around the
scan is what is pooled), never by the size of the map.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import attrs
import numpy as np

from .grid import LikelihoodGrid, max_tables

__all__ = ["CorrelativeMatcher", "MatchResult", "voxel_filter"]

_BLOCKS = (16, 4, 1)


@attrs.define(frozen=True, eq=False)
class MatchResult:
    """``pose``: best (x, y, theta) in the grid's frame; ``score``: mean likelihood of the hits
    there (0..1); ``covariance``: 3x3 (m^2, rad^2); ``ambiguous``: the response is flat over
    more than ``max_sd_xy`` / ``max_sd_theta`` (a corridor, a repetitive place); ``evaluated``:
    how many candidates branch and bound scored (the work done). ``hessian_covariance``: 3x3,
    from the curvature of the score at the polished pose (module docstring, step 4), in the
    grid's axes."""

    pose: np.ndarray
    score: float
    covariance: np.ndarray
    ambiguous: bool
    evaluated: int
    hessian_covariance: np.ndarray


def voxel_filter(points: np.ndarray, size: float) -> np.ndarray:
    """One point per ``size`` square (the first in scan order): near walls are hit by many more
    beams than far ones; without this they dominate the score."""
    if len(points) == 0 or size <= 0:
        return points
    keys = np.floor(points / size).astype(np.int64)
    _, first = np.unique(keys[:, 0] * 1_000_003 + keys[:, 1], return_index=True)
    return points[np.sort(first)]


@attrs.define(kw_only=True)
class CorrelativeMatcher:
    """Parameters: ``angular_step`` (rad; 0 = from the hits: one cell at the 90th-percentile
    range, clamped to [``min_angular_step``, ``max_angular_step``]); ``cov_cells``,
    ``cov_steps``, ``cov_tau``: the covariance neighbourhood and temperature; ``max_sd_xy`` (m)
    and ``max_sd_theta`` (rad): beyond these a match is ambiguous; ``polish_iterations``;
    ``cov_with_prior``: the covariance from the scores with the prior (default) or without."""

    angular_step: float = 0.0
    min_angular_step: float = math.radians(0.25)
    max_angular_step: float = math.radians(1.0)
    cov_cells: int = 6
    cov_steps: int = 3
    cov_tau: float = 0.03
    max_sd_xy: float = 0.08
    max_sd_theta: float = math.radians(2.0)
    polish_iterations: int = 10
    polish: str = attrs.field(default="bilinear", validator=attrs.validators.in_(("bilinear", "distance")))
    polish_trim: float = 0.0
    # Whether the response covariance is taken from the scores with the prior towards the guess
    # (True: the old behaviour) or from the scan's own scores (False). The prior is the
    # odometry, which the pose graph already holds as a factor of its own.
    cov_with_prior: bool = True

    def _step(self, points: np.ndarray, resolution: float) -> float:
        if self.angular_step > 0:
            return self.angular_step
        far = float(np.percentile(np.hypot(points[:, 0], points[:, 1]), 90)) if len(points) else 1.0
        return min(max(resolution / max(far, 1e-3), self.min_angular_step), self.max_angular_step)

    def match(self, grid: LikelihoodGrid, guess: np.ndarray, points: np.ndarray, *, window_xy: float,
              window_theta: float, min_score: float = 0.0, prior_weight: float = 0.0,
              prior_sigma: tuple[float, float] = (0.1, 0.05)) -> MatchResult | None:
        """Best pose of the hits ``points`` (N, 2, robot frame) in ``grid`` within the window
        around ``guess``; None when no candidate scores above ``min_score`` (or no hits/map)."""
        guess = np.asarray(guess, dtype=np.float64)
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if len(pts) == 0 or grid.hits == 0:
            return None
        r = grid.resolution
        step = self._step(pts, r)
        na = int(math.ceil(window_theta / step))
        dth = step * np.arange(-na, na + 1)
        w = int(math.ceil(window_xy / r))
        yaws = guess[2] + dth
        c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
        wx = c * pts[:, 0] - s * pts[:, 1] + guess[0]
        wy = s * pts[:, 0] + c * pts[:, 1] + guess[1]
        bx = np.floor((wx - grid.origin[0]) / r).astype(np.int64)  # (A, N) cell of each hit at offset 0
        by = np.floor((wy - grid.origin[1]) / r).astype(np.int64)
        pad = w + max(self.cov_cells, 0) + _BLOCKS[0] + 1
        lo = np.array([bx.min() - pad, by.min() - pad])
        shape = (int(by.max() - lo[1] + pad + 1), int(bx.max() - lo[0] + pad + 1))
        field = grid.crop(lo, shape)
        tables = max_tables(field, list(_BLOCKS))
        bx -= lo[0]
        by -= lo[1]
        inv_n = 1.0 / len(pts)
        sxy, sth = prior_sigma

        def prior_bound(a: np.ndarray, u: np.ndarray, v: np.ndarray, b: int) -> np.ndarray:
            if prior_weight <= 0:
                return np.ones(len(a))
            ue = np.minimum(u + b - 1, w)
            ve = np.minimum(v + b - 1, w)
            du = np.where((u <= 0) & (ue >= 0), 0, np.minimum(np.abs(u), np.abs(ue))) * r
            dv = np.where((v <= 0) & (ve >= 0), 0, np.minimum(np.abs(v), np.abs(ve))) * r
            m = (du * du + dv * dv) / (sxy * sxy) + (dth[a] / sth) ** 2
            return np.exp(-0.5 * prior_weight * m)

        evaluated = 0

        def score(a: np.ndarray, u: np.ndarray, v: np.ndarray, b: int, prior: bool = True) -> np.ndarray:
            nonlocal evaluated
            evaluated += len(a)
            t = tables[b]
            raw = t[by[a] + v[:, None], bx[a] + u[:, None]].sum(axis=1) * inv_n
            return raw * prior_bound(a, u, v, b) if prior else raw

        top = _BLOCKS[0]
        offs = np.arange(-w, w + 1, top)
        aa, uu, vv = np.meshgrid(np.arange(len(dth)), offs, offs, indexing="ij")
        a0, u0, v0 = aa.ravel(), uu.ravel(), vv.ravel()
        best = self._branch(score, a0, u0, v0, 0, w, min_score)
        if best is None:
            return None
        ba, bu, bv, bscore = best
        pose = np.array([guess[0] + bu * r, guess[1] + bv * r, yaws[ba]])
        cov = self._covariance(score, ba, bu, bv, bscore, len(dth), w, r, step)
        offset = lo * r + grid.origin
        if self.polish == "distance":
            pose, polished = _polish_distance(field, offset, r, grid.sigma, pts, pose, self.polish_iterations,
                                              self.polish_trim)
        else:
            pose, polished = self._polish(field, offset, r, pts, pose)
        hess = self._hessian_covariance(field, offset, r, pts, pose, step, window_xy, window_theta)
        sd_xy = math.sqrt(max(float(np.linalg.eigvalsh(cov[:2, :2]).max()), 0.0))
        ambiguous = sd_xy > self.max_sd_xy or math.sqrt(cov[2, 2]) > self.max_sd_theta
        return MatchResult(pose=pose, score=polished, covariance=cov, ambiguous=ambiguous, evaluated=evaluated,
                           hessian_covariance=hess)

    def _branch(self, score, a: np.ndarray, u: np.ndarray, v: np.ndarray, level: int, w: int,
                min_score: float) -> tuple[int, int, int, float] | None:
        """Depth-first branch and bound (Cartographer's order): best child first, prune any
        block whose bound is not above the best complete candidate so far."""
        b = _BLOCKS[level]
        sc = score(a, u, v, b)
        order = np.argsort(-sc)
        best: tuple[int, int, int, float] | None = None
        floor = min_score
        for k in order:
            if sc[k] <= floor:
                break
            if level == len(_BLOCKS) - 1:
                return int(a[k]), int(u[k]), int(v[k]), float(sc[k])
            nb = _BLOCKS[level + 1]
            sub = np.arange(0, b, nb)
            cu = u[k] + sub
            cv = v[k] + sub
            cu, cv = cu[cu <= w], cv[cv <= w]
            gu, gv = np.meshgrid(cu, cv, indexing="ij")
            ca = np.full(gu.size, a[k])
            found = self._branch(score, ca, gu.ravel(), gv.ravel(), level + 1, w, floor)
            if found is not None and found[3] > floor:
                best, floor = found, found[3]
        return best

    def _covariance(self, score, ba: int, bu: int, bv: int, bscore: float, n_angles: int, w: int,
                    r: float, step: float) -> np.ndarray:
        k, m = self.cov_cells, self.cov_steps
        du = np.arange(-k, k + 1)
        da = np.arange(max(ba - m, 0), min(ba + m, n_angles - 1) + 1)
        aa, uu, vv = np.meshgrid(da, bu + du, bv + du, indexing="ij")
        s = score(aa.ravel(), uu.ravel(), vv.ravel(), 1, self.cov_with_prior)
        wgt = np.exp((s - s.max()) / self.cov_tau)
        wgt /= wgt.sum()
        x = np.column_stack([uu.ravel() * r, vv.ravel() * r, aa.ravel() * step])
        mean = wgt @ x
        d = x - mean
        cov = (d * wgt[:, None]).T @ d
        # The lattice cannot resolve less than its own spacing.
        cov += np.diag([r * r / 12.0, r * r / 12.0, step * step / 12.0])
        return cov

    def _polish(self, field: np.ndarray, offset: np.ndarray, r: float, pts: np.ndarray,
                pose: np.ndarray) -> tuple[np.ndarray, float]:
        """Levenberg-Marquardt on sum (1 - M(T p))^2 with M the bilinear field; returns the
        pose and its mean likelihood. A step that does not lower the cost is refused."""
        h, wd = field.shape

        def sample(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
            c, s = math.cos(p[2]), math.sin(p[2])
            x = c * pts[:, 0] - s * pts[:, 1] + p[0]
            y = s * pts[:, 0] + c * pts[:, 1] + p[1]
            fx = (x - offset[0]) / r - 0.5
            fy = (y - offset[1]) / r - 0.5
            i0 = np.clip(np.floor(fx).astype(np.int64), 0, wd - 2)
            j0 = np.clip(np.floor(fy).astype(np.int64), 0, h - 2)
            t = np.clip(fx - i0, 0.0, 1.0)
            u = np.clip(fy - j0, 0.0, 1.0)
            f00, f01 = field[j0, i0], field[j0, i0 + 1]
            f10, f11 = field[j0 + 1, i0], field[j0 + 1, i0 + 1]
            m = (1 - t) * (1 - u) * f00 + t * (1 - u) * f01 + (1 - t) * u * f10 + t * u * f11
            gx = ((1 - u) * (f01 - f00) + u * (f11 - f10)) / r
            gy = ((1 - t) * (f10 - f00) + t * (f11 - f01)) / r
            # d(world point)/d(theta)
            dxt = -s * pts[:, 0] - c * pts[:, 1]
            dyt = c * pts[:, 0] - s * pts[:, 1]
            jac = -np.column_stack([gx, gy, gx * dxt + gy * dyt])  # d(1 - M)/d(x, y, theta)
            return 1.0 - m, jac, m, np.array(0)

        res, jac, m, _ = sample(pose)
        pose, m = _levenberg_marquardt(lambda p: sample(p)[:3], pose, res, jac, m, self.polish_iterations, r)
        return pose, float(m.mean())

    @staticmethod
    def _hessian_covariance(field: np.ndarray, offset: np.ndarray, r: float, pts: np.ndarray, pose: np.ndarray,
                            step: float, window_xy: float, window_theta: float) -> np.ndarray:
        """``(N H)^-1``, ``H`` the curvature (minus the Hessian) of the mean score at the
        polished pose, ``N`` the hit count: each hit on a wall of the Gaussian field
        ``exp(-d^2 / 2 sigma^2)`` adds ``1 / sigma^2`` of curvature across the wall and none along
        it, exactly the information of a measurement with standard deviation ``sigma``; so this
        is the covariance the hits would give if they were independent. Central differences of
        the bilinear field with steps of two cells and two lattice heading steps: the field is
        piecewise linear (its curvature only exists at the scale of a cell), and along a wall far
        from the scanner its hits are farther apart than the field's reach, so at one cell the
        bumps between them would read as information along the wall. Across a wall this step
        (2 sigma) reads about half the curvature at the crest, a constant factor the
        calibration absorbs. Along a corridor the score is flat and the direction gets (almost)
        no information. Negative curvature (not a maximum in
        some direction) counts as none. The search window bounds what a match can claim not to
        know: the information is at least that of a Gaussian as wide as the window."""
        h = np.array([2.0 * r, 2.0 * r, 2.0 * step])
        offsets = [np.zeros(3)]
        for i in range(3):
            e = np.zeros(3)
            e[i] = h[i]
            offsets += [e, -e]
        for i in range(3):
            for j in range(i + 1, 3):
                for si in (1, -1):
                    for sj in (1, -1):
                        e = np.zeros(3)
                        e[i], e[j] = si * h[i], sj * h[j]
                        offsets.append(e)
        cand = pose + np.array(offsets)  # (19, 3)
        c, s = np.cos(cand[:, 2])[:, None], np.sin(cand[:, 2])[:, None]
        fx = (c * pts[:, 0] - s * pts[:, 1] + cand[:, 0:1] - offset[0]) / r - 0.5
        fy = (s * pts[:, 0] + c * pts[:, 1] + cand[:, 1:2] - offset[1]) / r - 0.5
        hh, ww = field.shape
        i0 = np.clip(np.floor(fx).astype(np.int64), 0, ww - 2)
        j0 = np.clip(np.floor(fy).astype(np.int64), 0, hh - 2)
        t = np.clip(fx - i0, 0.0, 1.0)
        u = np.clip(fy - j0, 0.0, 1.0)
        m = ((1 - t) * (1 - u) * field[j0, i0] + t * (1 - u) * field[j0, i0 + 1]
             + (1 - t) * u * field[j0 + 1, i0] + t * u * field[j0 + 1, i0 + 1])
        sc = m.mean(axis=1)
        hess = np.zeros((3, 3))
        for i in range(3):
            hess[i, i] = (sc[1 + 2 * i] - 2 * sc[0] + sc[2 + 2 * i]) / (h[i] * h[i])
        k = 7
        for i in range(3):
            for j in range(i + 1, 3):
                pp, pm, mp, mm = sc[k:k + 4]
                hess[i, j] = hess[j, i] = (pp - pm - mp + mm) / (4 * h[i] * h[j])
                k += 4
        vals, vecs = np.linalg.eigh(-0.5 * (hess + hess.T))
        info = (vecs * np.maximum(vals, 0.0)) @ vecs.T * len(pts)
        info += np.diag([1.0 / window_xy ** 2, 1.0 / window_xy ** 2, 1.0 / window_theta ** 2])
        cov = np.linalg.inv(info)
        return 0.5 * (cov + cov.T)


def _keys_weights(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Keys' cubic convolution (a = -1/2, Catmull-Rom) weights of the four samples around a
    point at fraction ``t`` (N,) past the second, and their derivatives in ``t``: (4, N) each.
    It reproduces every polynomial of degree two exactly."""
    t2, t3 = t * t, t * t * t
    w = 0.5 * np.stack([-t + 2 * t2 - t3, 2 - 5 * t2 + 3 * t3, t + 4 * t2 - 3 * t3, -t2 + t3])
    dw = 0.5 * np.stack([-1 + 4 * t - 3 * t2, -10 * t + 9 * t2, 1 + 8 * t - 9 * t2, -2 * t + 3 * t2])
    return w, dw


def _bicubic(table: np.ndarray, fx: np.ndarray, fy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Keys bicubic interpolation of ``table`` (rows along y) at fractional cell-centre
    coordinates ``fx``, ``fy`` (N,), with its gradient in cells: (value, d/dfx, d/dfy). Points
    within one cell of the border are clamped to it (the caller's crop is padded)."""
    h, wd = table.shape
    i0 = np.clip(np.floor(fx).astype(np.int64), 1, wd - 3)
    j0 = np.clip(np.floor(fy).astype(np.int64), 1, h - 3)
    wx, dwx = _keys_weights(np.clip(fx - i0, 0.0, 1.0))
    wy, dwy = _keys_weights(np.clip(fy - j0, 0.0, 1.0))
    k = np.arange(-1, 3)
    patch = table[(j0[None, :] + k[:, None])[:, None, :], (i0[None, :] + k[:, None])[None, :, :]]  # (4y, 4x, N)
    rows = np.einsum("xn,yxn->yn", wx, patch)
    drows = np.einsum("xn,yxn->yn", dwx, patch)
    return np.einsum("yn,yn->n", wy, rows), np.einsum("yn,yn->n", wy, drows), np.einsum("yn,yn->n", dwy, rows)


def _levenberg_marquardt(sample: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]], pose: np.ndarray,
                         res: np.ndarray, jac: np.ndarray, m: np.ndarray, iterations: int, r: float) -> tuple[np.ndarray, np.ndarray]:
    """The polishes' Levenberg-Marquardt on ``sum(res^2)``: ``sample(pose)`` gives the residuals,
    their Jacobian in (x, y, theta) and the hits' likelihoods; ``res``, ``jac``, ``m`` are its
    answer at the starting ``pose``. A step that does not lower the cost is refused, and a step
    larger than a lattice cell ``r`` (or a degree) is damped: the polish refines the lattice
    search's pose, it never leaves its cell by much. Returns the pose and its likelihoods."""
    cost = float(res @ res)
    lam = 1e-3
    for _ in range(iterations):
        a = jac.T @ jac
        g = jac.T @ res
        try:
            delta = -np.linalg.solve(a + lam * np.diag(np.diag(a) + 1e-9), g)
        except np.linalg.LinAlgError:
            break
        if abs(delta[0]) > r or abs(delta[1]) > r or abs(delta[2]) > math.radians(1.0):
            lam *= 10.0
            continue
        cand = pose + delta
        res2, jac2, m2 = sample(cand)
        cost2 = float(res2 @ res2)
        if cost2 < cost:
            pose, res, jac, m, cost = cand, res2, jac2, m2, cost2
            lam = max(lam / 10.0, 1e-7)
            if np.abs(delta).max() < 1e-5:
                break
        else:
            lam *= 10.0
    return pose, m


def _polish_distance(field: np.ndarray, offset: np.ndarray, r: float, sigma: float, pts: np.ndarray,
                     pose: np.ndarray, iterations: int, trim: float) -> tuple[np.ndarray, float]:
    """The sub-cell polish without the lattice's bias: Levenberg-Marquardt on the same cost as
    the bilinear polish, sum (1 - M)^2, but with ``M = exp(-D / 2 sigma^2)`` where ``D`` is the
    bicubic (Keys) interpolation of the squared distance to the nearest hit, recovered from the
    field as ``D = -2 sigma^2 ln(field)`` (capped where the field is 0, beyond its reach).

    Why: any bilinear interpolant has its maxima on the samples, so with the bilinear field a
    wall's hits are pulled onto the nearest row of cell centres, by up to half a cell (2.5 cm),
    the same way for every hit of a wall parallel to the grid: a bias, not noise. Across a
    wall ``D`` is exactly quadratic, ``(x - x_wall)^2``, and Keys' cubic reproduces quadratics
    exactly, so the interpolated crest lies on the wall wherever it falls between samples.
    Returns the pose and the mean ``M`` of the hits there."""
    reach2 = float(np.float32(-2.0 * sigma * sigma * math.log(1e-6)))
    with np.errstate(divide="ignore"):
        d2 = np.where(field > 1e-6, -2.0 * sigma * sigma * np.log(np.maximum(field, 1e-30)), reach2)
    inv2s2 = 0.5 / (sigma * sigma)

    def sample(p: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        c, s = math.cos(p[2]), math.sin(p[2])
        x = c * pts[:, 0] - s * pts[:, 1] + p[0]
        y = s * pts[:, 0] + c * pts[:, 1] + p[1]
        dist2, gx, gy = _bicubic(d2, (x - offset[0]) / r - 0.5, (y - offset[1]) / r - 0.5)
        dist2 = np.clip(dist2, 0.0, reach2)
        m = np.exp(-inv2s2 * dist2)
        # d(1 - M)/d(world) = M / (2 sigma^2) * dD/d(world); dD/d(world) = dD/d(cell) / r.
        k = m * inv2s2 / r
        dxt = -s * pts[:, 0] - c * pts[:, 1]
        dyt = c * pts[:, 0] - s * pts[:, 1]
        jac = np.column_stack([k * gx, k * gy, k * (gx * dxt + gy * dyt)])
        return 1.0 - m, jac, m

    used = pts
    res, jac, m = sample(pose, used)
    # Hits farther than ``trim`` sigma from every submap hit at the lattice pose are not used:
    # the submap has not seen what they hit (a wall past the end of the part it knows), so they
    # carry no information, only the pull of the tail of the nearest known hit's Gaussian back
    # along the wall: the bias that measured every step short. Fixed once, so the cost is smooth.
    if trim > 0:
        keep = m >= math.exp(-0.5 * trim * trim)
        if np.count_nonzero(keep) >= 3:
            used = pts[keep]
            res, jac, m = res[keep], jac[keep], m[keep]
    pose, _ = _levenberg_marquardt(lambda p: sample(p, used), pose, res, jac, m, iterations, r)
    return pose, float(sample(pose, pts)[2].mean())  # the score of every hit, as the search's
