"""Cost-to-go over a grid: Dijkstra from the goal on an 8-connected lattice (scipy, in C).

The field answers "how far (in clearance-weighted metres) is the goal from here" for every
cell at once, which the local planner uses to score candidate arcs, and it yields the global
path by following predecessors.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

#: m beyond the robot's half-width where travel is allowed but costly (``soft_weight``): gaps only
#: a little wider than the robot need more precision than sampled arcs have, and a plan through
#: them tends to get the robot stuck. All 250 shipped BARN worlds keep a route outside this band
#: up to 0.13 m (tests/sim/test_sim_barn.py checks the default).
CLEARANCE_BAND = 0.08
#: m beyond the band over which the corridor-centring penalty fades out
CENTRING_RANGE = 0.45


def footprint_field(shape: tuple[int, int], resolution: float, half_width: float,
                    band: float = CLEARANCE_BAND, centring: float = CENTRING_RANGE) -> CostField:
    """The cost field every navigation layer uses for a robot of half-width ``half_width``
    (a box's half-width, a disc's radius: the largest circle inside the footprint): lethal
    closer than the half-width (less half a cell, since obstacles fill their cells: the robot
    touches there whatever its heading), costly up to ``band`` beyond it, a centring penalty
    fading out ``centring`` further. The global planner, the in-process navigator and the
    arc sampler's local field share it, so a route one of them takes the others accept."""
    lethal = max(half_width - 0.5 * resolution, 0.05)
    soft = half_width + band
    return CostField(shape, resolution, lethal, inflation_radius=soft + centring, soft_radius=soft)


def tightest_spot(plan: np.ndarray, clearance_at: Callable[[np.ndarray], np.ndarray], robot_xy: Sequence[float] | np.ndarray,
                  keep_out: float, ahead: float = 2.5) -> tuple[float, float] | None:
    """The point of the next ``ahead`` m of ``plan`` (N, >= 2) with the least clearance, at
    least ``keep_out`` m from the robot (never block the ground it stands on: that would box
    it in); None if no such point. Where a plan that makes no progress should be blocked."""
    plan = np.asarray(plan, dtype=float)[:, :2]
    if len(plan) < 2:
        return None
    seg = np.linalg.norm(np.diff(plan, axis=0), axis=1)
    near = plan[: int(np.searchsorted(np.cumsum(seg), ahead)) + 1]
    near = near[np.hypot(near[:, 0] - robot_xy[0], near[:, 1] - robot_xy[1]) > keep_out]
    if len(near) == 0:
        return None
    x, y = near[int(np.argmin(clearance_at(near)))]
    return float(x), float(y)


def _scipy():
    try:
        from scipy import ndimage
        from scipy.sparse import csgraph, csr_matrix
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("the cost-to-go planner needs scipy: pip install 'emos[nav]'") from exc
    return ndimage, csgraph, csr_matrix


def lattice_edges(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undirected 8-neighbour edges of a (rows, cols) grid: (a, b, length in cells)."""
    rows, cols = shape
    idx = np.arange(rows * cols).reshape(shape)
    a, b, lengths = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        # Source cells are those whose (dr, dc) neighbour is inside the grid.
        s0, s1 = (0, cols - dc) if dc >= 0 else (-dc, cols)
        src = idx[: rows - dr, s0:s1]
        dst = idx[dr:, s0 + dc: s1 + dc]
        a.append(src.ravel())
        b.append(dst.ravel())
        lengths.append(np.full(src.size, math.hypot(dr, dc)))
    return np.concatenate(a), np.concatenate(b), np.concatenate(lengths)


class CostField:
    """``lethal_radius``: cells closer than this to an obstacle are impassable. Between it and
    ``soft_radius`` a cell costs ``soft_weight`` times its length (possible, but only when
    nothing else is); beyond, a penalty fading out at ``inflation_radius`` keeps paths
    centred in corridors. A soft band instead of a hard wall keeps the field smooth, so a
    robot that finds itself close to obstacles still sees a way out downhill."""

    def __init__(self, shape: tuple[int, int], resolution: float, lethal_radius: float,
                 inflation_radius: float = 0.6, inflation_weight: float = 3.0,
                 soft_radius: float | None = None, soft_weight: float = 20.0) -> None:
        soft_radius = lethal_radius if soft_radius is None else soft_radius
        if not 0 <= lethal_radius <= soft_radius < inflation_radius:
            raise ValueError("CostField needs 0 <= lethal_radius <= soft_radius < inflation_radius, got "
                             f"{lethal_radius}, {soft_radius}, {inflation_radius}")
        self.shape, self.resolution = shape, float(resolution)
        self.lethal_radius, self.inflation_radius = lethal_radius, inflation_radius
        self.soft_radius, self.soft_weight = soft_radius, soft_weight
        self.inflation_weight = inflation_weight
        self._a, self._b, self._len = lattice_edges(shape)
        self.ctg = np.full(shape, np.inf)
        self.ctg_filled = np.full(shape, np.inf)
        self.clearance = np.full(shape, np.inf)
        self._pred = np.full(shape[0] * shape[1], -9999)

    def compute(self, occupied: np.ndarray, goal_cell: tuple[int, int], hit_xy: np.ndarray | None = None,
                origin: np.ndarray | None = None, extra_cost: np.ndarray | None = None) -> None:
        """Recompute cost-to-go for the obstacle cells ``occupied`` and the goal cell.

        ``extra_cost`` (the grid's shape, >= 0): a soft cost per cell added to the clearance
        penalty, e.g. where people walk (a cell of cost 3 costs four times its length).

        With ``hit_xy`` (rows, cols, 2: the exact obstacle point stored in each occupied cell)
        and the grid ``origin``, clearance is measured from cell centres to those exact points
        rather than to cell centres, so a gap narrower than the robot is not opened (or a wide
        one closed) by grid rounding.
        """
        ndimage, csgraph, csr_matrix = _scipy()

        n = self.shape[0] * self.shape[1]
        if occupied.any():
            dist, (ri, ci) = ndimage.distance_transform_edt(~occupied, return_indices=True)
            if hit_xy is not None and origin is not None:
                rows, cols = np.indices(self.shape)
                cx = origin[0] + (cols + 0.5) * self.resolution
                cy = origin[1] + (rows + 0.5) * self.resolution
                near = hit_xy[ri, ci]
                self.clearance = np.hypot(cx - near[..., 0], cy - near[..., 1])
            else:
                self.clearance = dist * self.resolution
        else:
            self.clearance = np.full(self.shape, np.inf)
        clear = self.clearance.ravel()
        free = clear > self.lethal_radius
        # Penalty grows as clearance shrinks towards the lethal radius: paths keep to the
        # middle of corridors unless squeezing through is the only way.
        span = self.inflation_radius - self.soft_radius
        closeness = np.clip((self.inflation_radius - clear) / span, 0.0, 1.0)
        penalty = np.where(clear <= self.soft_radius, self.soft_weight, self.inflation_weight * closeness**2)
        if extra_cost is not None:
            penalty = penalty + extra_cost.ravel()
        keep = free[self._a] & free[self._b]
        a, b = self._a[keep], self._b[keep]
        w = self._len[keep] * self.resolution * (1.0 + 0.5 * (penalty[a] + penalty[b]))
        graph = csr_matrix((w, (a, b)), shape=(n, n))
        goal = goal_cell[0] * self.shape[1] + goal_cell[1]
        dist, pred = csgraph.dijkstra(graph, directed=False, indices=goal, return_predecessors=True)
        self.ctg = dist.reshape(self.shape)
        self._pred = pred
        # Cells the field cannot reach (lethal, enclosed) take the value of the nearest
        # reachable cell plus a steep slope, so a local planner near obstacles still sees
        # which way is downhill instead of a flat wall of infinities.
        unreachable = ~np.isfinite(self.ctg)
        if unreachable.any() and not unreachable.all():
            gap, (ri, ci) = ndimage.distance_transform_edt(unreachable, return_indices=True)
            self.ctg_filled = np.where(unreachable, self.ctg[ri, ci] + 10.0 * gap * self.resolution, self.ctg)
            self._nearest_reachable: tuple[np.ndarray, np.ndarray] | None = (ri, ci)
        else:
            self.ctg_filled = self.ctg.copy()
            self._nearest_reachable = None

    def path_from(self, cell: tuple[int, int], max_len: int = 100_000) -> list[tuple[int, int]]:
        """Cells from ``cell`` to the goal following the shortest-path tree ([] if unreachable)."""
        cols = self.shape[1]
        node = cell[0] * cols + cell[1]
        if not np.isfinite(self.ctg[cell]):
            return []
        out = [cell]
        for _ in range(max_len):
            node = int(self._pred[node])
            if node < 0:
                break
            out.append((node // cols, node % cols))
        return out

    def escape_from(self, cell: tuple[int, int]) -> tuple[int, int] | None:
        """For a cell the field cannot reach (inside the lethal band: a robot pushed or
        localized closer to an obstacle than it can be planned through), the nearest cell it
        can; the cell itself when reachable; None when nothing is reachable."""
        if np.isfinite(self.ctg[cell]):
            return cell
        near = getattr(self, "_nearest_reachable", None)
        if near is None or self.clearance[cell] > self.lethal_radius:
            return None  # free but cut off from the goal: no escape, no path
        out = (int(near[0][cell]), int(near[1][cell]))
        # Only out of the band the robot stands in, never across a wall.
        if math.hypot(out[0] - cell[0], out[1] - cell[1]) * self.resolution > self.lethal_radius + self.resolution:
            return None
        return out if np.isfinite(self.ctg[out]) else None
