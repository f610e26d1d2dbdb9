"""Graph SLAM on 2D lidar scans and odometry: correlative scan-to-submap matching in front,
a gtsam pose graph with loop closures behind.

Each scan, in :meth:`GraphSlam.add`:

1. **Input check.** Ranges that are NaN, inf, <= ``min_range`` or >= ``max_range`` (no echo)
   are not hits; a scan whose beam count does not match its angles is not used at all (its node
   gets the odometry only); both are logged (rate-limited), naming the scan.
2. **Front end.** The odometry increment carries the previous front-end pose to a guess; the
   scan's hits (within ``match_range``, one per ``voxel`` square) are matched against the
   current submap by :class:`CorrelativeMatcher` in a window of ``window_sigmas`` standard
   deviations of the odometry noise model (clamped to ``[min_window_*, max_window_*]``), with a
   weak prior towards the guess (``prior_weight``: it decides only where the scan does not, e.g.
   along a featureless corridor; weak enough that a far end wall's few hits still fix the
   position along one). The hits are then inserted into the two newest submaps.
3. **Submaps** (as in Cartographer): a new submap starts every ``scans_per_submap`` scans (or
   ``submap_travel`` metres, when set) and each scan goes into the two newest, so a submap holds
   two periods' scans when it is finished, and the one matched against always has between one
   and two periods'. A submap is a rigid local map in the frame of its first scan's front-end
   pose.
4. **Back end.** Node = scan, plus one variable per submap frame (``submap_nodes``). An
   odometry factor (covariance from the motion model) to the previous node, and a scan-match
   factor from each submap the scan went into (its frame; without ``submap_nodes``, only from
   the matched submap's anchor node) (covariance from the
   match: ``factor_covariance="response"``, the spread of the lattice scores around the best
   pose (Olson) times ``match_cov_scale`` (per match: split over the scan's factors, so a match
   counts once) / ``loop_cov_scale``; or ``"hessian"``, the inverse
   curvature of the score at the polished pose over the hit count (``MatchResult.
   hessian_covariance``) times ``hessian_cov_scale``, the factor that calibrates it against
   the factors' real errors). Every ``loop_every`` scans, the scan is matched against up to
   ``loop_candidates`` finished submaps whose anchor lies within ``loop_radius`` of the
   scan's optimised pose (nearest first), each in a bounded window (``loop_window_xy``,
   ``loop_window_theta``) around where the graph puts it, with no prior. A loop closure is
   accepted only if its score reaches ``loop_min_score`` and its response is not ambiguous;
   it enters the graph under a robust (Huber or Cauchy) kernel. iSAM2 updates the graph.

Options (off by default; measured in docs/mapping.md): ``icp_polish`` refines each match (front
end and loop closure) by point-to-line ICP against the submap's hits (``scan_icp``), which the
likelihood-field polish is biased against where scan and submap overlap in part.
``refine_passes`` (default 1: better on every tuning log but aces, where it is equal;
docs/slam_notes.md) adds, after the batch (:meth:`GraphSlam.finish`, what ``emos map
build`` and ``emos bench slam`` end with), scan-to-scan ICP factors between each node and its
nearest earlier nodes and re-solves (no submap, so no frozen front-end pose, in those factors);
0 turns it off.
Measured in docs/slam_notes.md, also off by default: ``match_polish="distance"`` (the matcher's
bicubic squared-distance polish, unbiased where the bilinear one snaps walls to the lattice)
with ``polish_trim`` (hits the submap has not seen left out of the polish) and
``densify_gap`` (submap hits joined along surfaces, so that the field is the distance to the
wall, not to its sampled hits); ``submap_travel`` (a submap period also ends after that many
metres of travel, not only after ``scans_per_submap`` scans); the response covariance's
neighbourhood (``match_cov_cells`` cells, ``match_cov_steps`` heading steps; 6 and 3 by
default) and ``match_cov_prior=False`` (the covariance from the scan's own scores, without the
prior towards the odometry guess that the graph already holds as the odometry factor). On by
default (measured there
too): ``submap_nodes``, each submap's frame a graph variable of its own (as in Cartographer);
``submap_nodes=False`` is the older graph, in which the frame is its first scan's node.

Why the per-scan cost does not grow with the map: the front end only touches the current
submap (bounded: ``2 * scans_per_submap`` scans), matching cost is bounded by its window and the
hit count, loop closure tries a bounded number of submaps in a bounded window (finding the
candidates is a distance test over submap anchors: one vectorised pass over a few floats per
submap), and iSAM2 re-solves only the cliques a new factor touches. Memory grows with the
explored area (the finished submaps), not with time spent in it.
"""
from __future__ import annotations

import logging
import math
from typing import Any

import attrs
import numpy as np

from emos.config import validators as V
from emos.geometry import wrap_angle
from emos.ratelimit import RateLimitedLog

from ...localization.motion import compose_pose, odometry_delta, relative_pose
from .graph import PoseGraph
from .grid import LikelihoodGrid
from .matcher import CorrelativeMatcher, MatchResult, voxel_filter
from .scan_icp import IcpScan, icp_match

__all__ = ["GraphSlam", "SlamParams", "Submap", "relative_pose", "compose_pose", "scan_points"]

_log = logging.getLogger("emos.nav.mapping.slam")
_SUBMAP_KEY = 1 << 40  # graph keys of submap frames (``submap_nodes``): far above any scan index


@attrs.define(kw_only=True)
class SlamParams:
    """SLAM parameters (see the module docstring for what each does). Distances in m, angles
    in rad. ``odom_alphas``: the odometry noise (AMCL alpha1..alpha4) the front end's window and
    the odometry factors assume."""

    resolution: float = attrs.field(default=0.05, validator=V.finite_positive)
    sigma: float = attrs.field(default=0.05, validator=V.finite_positive)
    min_range: float = attrs.field(default=0.05, validator=attrs.validators.ge(0.0))
    max_range: float = attrs.field(default=30.0, validator=V.finite_positive)
    match_range: float = attrs.field(default=30.0, validator=V.finite_positive)
    voxel: float = attrs.field(default=0.1, validator=attrs.validators.ge(0.0))
    min_points: int = attrs.field(default=20, validator=attrs.validators.ge(3))
    scans_per_submap: int = attrs.field(default=10, validator=attrs.validators.ge(1))
    odom_alphas: tuple[float, float, float, float] = attrs.field(default=(0.02, 0.002, 0.02, 0.002))
    window_sigmas: float = attrs.field(default=3.0, validator=V.finite_positive)
    min_window_xy: float = attrs.field(default=0.2, validator=V.finite_positive)
    max_window_xy: float = attrs.field(default=1.0, validator=V.finite_positive)
    min_window_theta: float = attrs.field(default=math.radians(6.0), validator=V.finite_positive)
    max_window_theta: float = attrs.field(default=math.radians(45.0), validator=V.finite_positive)
    # 0.02, not 0.05: the prior only breaks ties. Along a corridor a far end wall is a few hits of
    # a hundred; at 0.05 a guess two odometry sigmas off outweighed them and the front end followed
    # the odometry's error (aces: corridors measured short). docs/slam_notes.md has the runs.
    prior_weight: float = attrs.field(default=0.02, validator=attrs.validators.ge(0.0))
    loop_every: int = attrs.field(default=1, validator=attrs.validators.ge(1))
    loop_radius: float = attrs.field(default=15.0, validator=V.finite_positive)
    loop_candidates: int = attrs.field(default=4, validator=attrs.validators.ge(1))
    loop_window_xy: float = attrs.field(default=1.5, validator=V.finite_positive)
    loop_window_theta: float = attrs.field(default=math.radians(15.0), validator=V.finite_positive)
    loop_min_score: float = attrs.field(default=0.55, validator=attrs.validators.and_(attrs.validators.ge(0.0), attrs.validators.le(1.0)))
    loop_skip_submaps: int = attrs.field(default=0, validator=attrs.validators.ge(0))
    confirm_after_nodes: int = attrs.field(default=60, validator=attrs.validators.ge(0))
    confirm_within: int = attrs.field(default=4, validator=attrs.validators.ge(1))
    confirm_xy: float = attrs.field(default=0.15, validator=V.finite_positive)
    confirm_theta: float = attrs.field(default=math.radians(2.0), validator=V.finite_positive)
    robust: str = attrs.field(default="huber", validator=attrs.validators.in_(("huber", "cauchy")))
    robust_k: float = attrs.field(default=1.345, validator=V.finite_positive)
    # The scale of one front-end match; with ``submap_nodes`` it is split over the factors the
    # match gives (one per submap the scan went into, usually two), so the graph counts the
    # measurement once. 0.2 (was 0.1, counted twice): docs/slam_notes.md has the runs.
    match_cov_scale: float = attrs.field(default=0.2, validator=V.finite_positive)
    loop_cov_scale: float = attrs.field(default=0.1, validator=V.finite_positive)
    factor_covariance: str = attrs.field(default="response", validator=attrs.validators.in_(("response", "hessian")))
    hessian_cov_scale: float = attrs.field(default=1.0, validator=V.finite_positive)
    icp_polish: bool = attrs.field(default=False, validator=attrs.validators.instance_of(bool))
    icp_prior_xy: float = attrs.field(default=0.0, validator=attrs.validators.ge(0.0))
    icp_prior_theta: float = attrs.field(default=0.02, validator=V.finite_positive)
    icp_min_conditioning: float = attrs.field(default=0.0, validator=attrs.validators.and_(attrs.validators.ge(0.0), attrs.validators.le(1.0)))
    icp_max_correction: float = attrs.field(default=0.2, validator=V.finite_positive)
    # One pass of scan-to-scan refinement after the batch: with submap frames in the graph it
    # lowers the ATE on the tuning logs (intel -5, csail -3 to -11 mm; aces within 1 mm) for a
    # few ms per scan, once, at the end. docs/slam_notes.md has the runs.
    refine_passes: int = attrs.field(default=1, validator=attrs.validators.ge(0))
    refine_radius: float = attrs.field(default=4.0, validator=V.finite_positive)
    refine_neighbours: int = attrs.field(default=8, validator=attrs.validators.ge(1))
    refine_min_overlap: float = attrs.field(default=0.3, validator=attrs.validators.and_(attrs.validators.ge(0.0), attrs.validators.le(1.0)))
    refine_cov_scale: float = attrs.field(default=30.0, validator=V.finite_positive)
    match_polish: str = attrs.field(default="bilinear", validator=attrs.validators.in_(("bilinear", "distance")))
    submap_nodes: bool = attrs.field(default=True, validator=attrs.validators.instance_of(bool))
    submap_travel: float = attrs.field(default=0.0, validator=attrs.validators.ge(0.0))
    polish_trim: float = attrs.field(default=0.0, validator=attrs.validators.ge(0.0))
    densify_gap: float = attrs.field(default=0.0, validator=attrs.validators.ge(0.0))
    match_cov_steps: int = attrs.field(default=3, validator=attrs.validators.ge(1))
    match_cov_cells: int = attrs.field(default=6, validator=attrs.validators.ge(1))
    match_cov_prior: bool = attrs.field(default=True, validator=attrs.validators.instance_of(bool))


@attrs.define(eq=False)
class Submap:
    """A rigid local map: the likelihood grid of ``2 * scans_per_submap`` scans placed at their
    front-end poses, anchored at node ``anchor`` (``anchor_pose``: its front-end pose)."""

    grid: LikelihoodGrid
    anchor: int
    anchor_pose: np.ndarray
    scans: int = 0
    finished: bool = False
    points: list[np.ndarray] = attrs.field(factory=list)  # world hits of each scan, for the ICP polish
    icp: IcpScan | None = None  # built from ``points`` when needed; None after an insertion
    key: int = -1  # the graph variable of the submap's frame: ``anchor``, or its own with ``submap_nodes``


def scan_points(ranges: np.ndarray, angles: np.ndarray, min_range: float, max_range: float) -> np.ndarray:
    """Hits (N, 2, sensor frame) of the readings that are finite and in (min_range, max_range)."""
    r = np.asarray(ranges, dtype=np.float64)
    a = np.asarray(angles, dtype=np.float64)
    ok = np.isfinite(r) & np.isfinite(a) & (r > min_range) & (r < max_range)
    return np.column_stack([r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])])


def densify(points: np.ndarray, max_gap: float, step: float) -> np.ndarray:
    """``points`` (N, 2, in beam order) plus points every ``step`` between consecutive hits at
    most ``max_gap`` apart (the surface both lie on). Why: the likelihood field is the Gaussian
    of the distance to the nearest *hit*; where a wall's hits are farther apart than a cell,
    that distance is a row of cones, not the distance to the wall, and the bicubic polish
    (``CorrelativeMatcher.polish = "distance"``), exact for a wall, is off by the bumps."""
    if len(points) < 2 or max_gap <= 0:
        return points
    gap = np.hypot(*np.diff(points, axis=0).T)
    extra = np.where(gap <= max_gap, np.maximum(np.ceil(gap / step).astype(np.int64) - 1, 0), 0)
    total = int(extra.sum())
    if not total:
        return points
    seg = np.repeat(np.arange(len(gap)), extra)
    # k-th added point of its segment: 1..extra[seg]
    k = np.arange(total) - np.repeat(np.cumsum(extra) - extra, extra) + 1
    t = (k / (extra[seg] + 1.0))[:, None]
    return np.concatenate([points, points[seg] + t * (points[seg + 1] - points[seg])])


class GraphSlam:
    """Online graph SLAM (see the module docstring). ``add`` one scan with its odometry pose at
    a time; ``trajectory()`` is the current estimate, ``finish()`` the batch-optimised one."""

    def __init__(self, params: SlamParams | None = None, *, name: str = "slam",
                 logger: logging.Logger | None = None) -> None:
        self.params = params or SlamParams()
        self.name = name
        self._logger = logger or _log
        self._report = RateLimitedLog(interval=5.0)
        self.matcher = CorrelativeMatcher(polish=self.params.match_polish, polish_trim=self.params.polish_trim,
                                          cov_steps=self.params.match_cov_steps, cov_cells=self.params.match_cov_cells,
                                          cov_with_prior=self.params.match_cov_prior)
        self.graph = PoseGraph(robust=self.params.robust, robust_k=self.params.robust_k)
        self.submaps: list[Submap] = []
        self.front: list[np.ndarray] = []  # front-end pose of each node
        self.odom: list[np.ndarray] = []
        self.matches = 0
        self.loop_attempts = 0
        self.loops: list[tuple[int, int, float]] = []  # (submap anchor, node, score)
        self.problems: dict[str, int] = {}
        self._guess = np.zeros(3)
        self._pending: list[tuple[int, np.ndarray, Submap, MatchResult]] = []
        self._accepted: set[tuple[int, int]] = set()
        self._scans: list[np.ndarray] = []  # each node's hits (sensor frame), for the refinement
        self._icp: dict[int, IcpScan] = {}
        self._inserted: list[Submap] = []  # the submaps the newest scan went into
        self._start_submap = False  # the next scan starts a submap
        self._period_scans = 0  # scans and front-end travel (m) since the newest submap started
        self._period_travel = 0.0

    # -- input ---------------------------------------------------------------------------------
    def _problem(self, key: str, msg: str, *args: Any) -> None:
        self.problems[key] = self.problems.get(key, 0) + 1
        self._report.warning((self.name, key), msg, *args, logger=self._logger)

    def _hits(self, index: int, ranges: Any, angles: Any) -> np.ndarray | None:
        p = self.params
        r = np.asarray(ranges, dtype=np.float64).ravel()
        a = np.asarray(angles, dtype=np.float64).ravel()
        if r.shape != a.shape:
            self._problem("beam_count", "%s: scan %d has %d ranges for %d beam angles; expected equal counts: "
                          "scan not used (odometry only)", self.name, index, r.size, a.size)
            return None
        bad = int(np.count_nonzero(~np.isfinite(r)))
        if bad:
            self._problem("nonfinite", "%s: scan %d has %d NaN/inf ranges of %d; they are not hits",
                          self.name, index, bad, r.size)
        return scan_points(r, a, p.min_range, p.max_range)

    # -- odometry model ------------------------------------------------------------------------
    def _odom_cov(self, delta: np.ndarray) -> np.ndarray:
        """Covariance (frame of the new pose, x y theta) of an odometry increment under the
        AMCL odometry model with ``odom_alphas`` (first order), with a floor. The increment is
        split as the model splits it (turn ``rot1`` towards the direction of travel, ``trans``,
        turn ``rot2``; Nav2's 1 cm threshold, reverse moves taken modulo pi): a short move
        sideways is two large turns for the model, each with its own noise, and the search
        window must cover that."""
        a1, a2, a3, a4 = self.params.odom_alphas
        rot1, trans, rot2 = odometry_delta(np.zeros(3), delta, 0.01)
        r1 = min(abs(rot1), abs(float(wrap_angle(rot1 - math.pi))))
        r2 = min(abs(rot2), abs(float(wrap_angle(rot2 - math.pi))))
        var_rot1 = a1 * r1 * r1 + a2 * trans * trans
        var_rot2 = a1 * r2 * r2 + a2 * trans * trans
        var_trans = a3 * trans * trans + a4 * (r1 * r1 + r2 * r2)
        sd_floor = (0.01, 0.01, math.radians(0.5))
        return np.diag([var_trans + sd_floor[0] ** 2, trans * trans * var_rot1 + sd_floor[1] ** 2,
                        var_rot1 + var_rot2 + sd_floor[2] ** 2])

    def _window(self, delta: np.ndarray) -> tuple[float, float]:
        p = self.params
        cov = self._odom_cov(delta)
        k = p.window_sigmas
        wxy = min(max(k * math.sqrt(max(cov[0, 0], cov[1, 1])), p.min_window_xy), p.max_window_xy)
        wth = min(max(k * math.sqrt(cov[2, 2]), p.min_window_theta), p.max_window_theta)
        return wxy, wth

    # -- main step -----------------------------------------------------------------------------
    def add(self, odom_pose: Any, ranges: Any, angles: Any) -> np.ndarray:
        """One scan taken at odometry pose ``odom_pose`` (x, y, theta); returns the node's
        current optimised pose."""
        p = self.params
        i = len(self.front)
        odom = np.asarray(odom_pose, dtype=np.float64).reshape(3)
        if not np.isfinite(odom).all():
            self._problem("odom", "%s: scan %d has a non-finite odometry pose %s; holding the last one",
                          self.name, i, odom.tolist())
            odom = self.odom[-1].copy() if self.odom else np.zeros(3)
        pts = self._hits(i, ranges, angles)
        if i == 0:
            guess = odom.copy()
            delta = np.zeros(3)
        else:
            delta = relative_pose(self.odom[-1], odom)
            guess = compose_pose(self.front[-1], delta)
        local = np.zeros((0, 2)) if pts is None else pts
        near = local[np.hypot(local[:, 0], local[:, 1]) < p.match_range] if len(local) else local
        match_pts = voxel_filter(near, p.voxel)
        pose = guess
        match: MatchResult | None = None
        target = self._target()
        if target is not None and len(match_pts) >= p.min_points:
            wxy, wth = self._window(delta)
            sd = self._odom_cov(delta)
            match = self.matcher.match(target.grid, guess, match_pts, window_xy=wxy, window_theta=wth,
                                       prior_weight=p.prior_weight,
                                       prior_sigma=(max(math.sqrt(max(sd[0, 0], sd[1, 1])), 0.02), max(math.sqrt(sd[2, 2]), 0.01)))
            if match is not None:
                match = self._icp_polish(target, match, near)
                pose = match.pose
                self.matches += 1
        elif pts is not None and len(match_pts) < p.min_points and i > 0:
            self._problem("few_hits", "%s: scan %d has %d usable hits (< %d); odometry only", self.name, i,
                          len(match_pts), p.min_points)
        self.front.append(pose)
        self.odom.append(odom)
        self._scans.append(near)
        self._insert(i, pose, near)
        self._add_to_graph(i, delta, target, match)
        closed = False
        if i % p.loop_every == 0 and len(match_pts) >= p.min_points:
            closed = self._close_loops(i, match_pts)
        self.graph.update(extra_iterations=2 if closed else 0)
        return self.graph.pose(i)

    def _target(self) -> Submap | None:
        live = [s for s in self.submaps[-2:] if not s.finished and s.grid.hits]
        return live[0] if live else None

    def _insert(self, i: int, pose: np.ndarray, local: np.ndarray) -> None:
        p = self.params
        if i > 0:
            self._period_travel += math.hypot(pose[0] - self.front[i - 1][0], pose[1] - self.front[i - 1][1])
        if i == 0 or self._start_submap:
            key = _SUBMAP_KEY + len(self.submaps) if p.submap_nodes else i
            self.submaps.append(Submap(grid=LikelihoodGrid(p.resolution, p.sigma, margin=5.0), anchor=i,
                                       anchor_pose=pose.copy(), key=key))
            self._start_submap, self._period_scans, self._period_travel = False, 0, 0.0
        self._inserted = []
        if len(local):
            c, s = math.cos(pose[2]), math.sin(pose[2])
            world = np.column_stack([c * local[:, 0] - s * local[:, 1] + pose[0],
                                     s * local[:, 0] + c * local[:, 1] + pose[1]])
            if p.densify_gap > 0:
                world = densify(world, p.densify_gap, p.resolution / 2.0)
            for sm in self.submaps[-2:]:
                if sm.finished:
                    continue
                sm.grid.insert(world)
                self._inserted.append(sm)
                if p.icp_polish:
                    sm.points.append(world)
                    sm.icp = None
                sm.scans += 1
        self._period_scans += 1
        # A period ends after ``scans_per_submap`` scans or ``submap_travel`` metres of front-end
        # travel: the next scan starts a submap, and the older live one, which has had two
        # periods, is finished.
        if self._period_scans >= p.scans_per_submap or 0 < p.submap_travel <= self._period_travel:
            self._start_submap = True
            if len(self.submaps) >= 2:
                self.submaps[-2].finished = True

    def _add_to_graph(self, i: int, delta: np.ndarray, target: Submap | None, match: MatchResult | None) -> None:
        g = self.graph
        if i == 0:
            self._guess = self.front[0].copy()
            g.add_node(0, self.front[0])
            g.add_prior(0, self.front[0], np.diag([1e-6, 1e-6, 1e-8]))
        else:
            prev = g.pose(i - 1)
            # The graph's pose of the new node before this step's update: where loop closure looks.
            self._guess = compose_pose(prev, relative_pose(self.front[i - 1], self.front[i]))
            g.add_node(i, self._guess)
            g.add_between(i - 1, i, delta, self._odom_cov(delta))
        if self.params.submap_nodes:
            self._insertion_factors(i, match)
        elif match is not None and target is not None and target.anchor != i:
            self._match_factor(target, i, match.pose, match.covariance, loop=False, hess=match.hessian_covariance)

    def _insertion_factors(self, i: int, match: MatchResult | None) -> None:
        """With ``submap_nodes`` (Cartographer's graph): each submap's frame is a variable of
        its own, and every scan gets a factor to each submap it went into, at its front-end pose
        there. Why: with the frame on the anchor scan's node, all of a submap's factors hang on
        that one scan, which loop closures then pull away from its neighbours (on csail the
        anchors stood 1 to 1.5 degrees off their neighbours, where scan-to-scan ICP agreed with
        the neighbours); a frame of its own is held by all 20 of its scans instead. A scan with
        no match (too few hits) gets no factor (as before): the odometry places it. The factors
        share one measurement (the match), so each carries its covariance times the number of
        factors: together they hold the match's information once, not twice."""
        g = self.graph
        new = self.submaps[-1] if self.submaps and self.submaps[-1].anchor == i else None
        if new is not None:
            g.add_variable(new.key, self._guess)
        if match is None:
            if new is not None:  # the frame needs a tie to the graph all the same
                g.add_between(new.key, i, np.zeros(3), np.diag([1e-4, 1e-4, 1e-6]))
            return
        share = len(self._inserted)
        for sm in self._inserted:  # the matched submap and the newer one share the scan's pose
            self._match_factor(sm, i, self.front[i], match.covariance * share, loop=False,
                               hess=match.hessian_covariance * share)

    def _match_factor(self, sm: Submap, i: int, pose: np.ndarray, cov: np.ndarray, loop: bool,
                      hess: np.ndarray | None = None) -> None:
        rel = relative_pose(sm.anchor_pose, pose)
        # The matcher's covariance is in the grid's axes; the factor's error is in the node's.
        c, s = math.cos(pose[2]), math.sin(pose[2])
        rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        p = self.params
        if p.factor_covariance == "hessian" and hess is not None:
            cov, scale = hess, p.hessian_cov_scale
        else:
            scale = p.loop_cov_scale if loop else p.match_cov_scale
        self.graph.add_between(sm.key, i, rel, scale * rot @ cov @ rot.T, loop=loop)

    def _close_loops(self, i: int, pts: np.ndarray) -> bool:
        p = self.params
        done = [s for s in self.submaps if s.finished]
        recent = {s.anchor for s in self.submaps[-(p.loop_skip_submaps + 2):]}
        cands = [s for s in done if s.anchor not in recent]
        if not cands:
            return False
        here = self._guess
        anchors = np.array([self.graph.pose(s.key) for s in cands])
        dist = np.hypot(anchors[:, 0] - here[0], anchors[:, 1] - here[1])
        order = [k for k in np.argsort(dist) if dist[k] <= p.loop_radius][: p.loop_candidates]
        closed = False
        for k in order:
            sm = cands[k]
            guess = compose_pose(sm.anchor_pose, relative_pose(anchors[k], here))
            self.loop_attempts += 1
            m = self.matcher.match(sm.grid, guess, pts, window_xy=p.loop_window_xy, window_theta=p.loop_window_theta,
                                   min_score=p.loop_min_score)
            if m is None or m.ambiguous or m.score < p.loop_min_score:
                continue
            m = self._icp_polish(sm, m, pts)
            # How far the match moves the scan from where the graph has it (in the submap's frame).
            correction = relative_pose(guess, m.pose)
            if i - sm.anchor > p.confirm_after_nodes and not self._confirmed(i, correction):
                self._pending.append((i, correction, sm, m))
                continue
            closed |= self._accept_loop(sm, i, m)
        return closed

    def _confirmed(self, i: int, correction: np.ndarray) -> bool:
        """A distant loop closure is accepted only when another scan of the last
        ``confirm_within`` nodes proposed the same correction of the graph (within
        ``confirm_xy``, ``confirm_theta``): a repetitive building fools one match, rarely two
        different scans into the same wrong place. The confirming candidate is accepted too."""
        p = self.params
        self._pending = [c for c in self._pending if i - c[0] <= p.confirm_within]
        ok = False
        for j, corr, sm, m in self._pending:
            if j == i:
                continue
            diff = relative_pose(corr, correction)
            if math.hypot(diff[0], diff[1]) <= p.confirm_xy and abs(diff[2]) <= p.confirm_theta:
                ok = True
                if (sm.anchor, j) not in self._accepted:
                    self._accept_loop(sm, j, m)
        return ok

    def _accept_loop(self, sm: Submap, i: int, m: MatchResult) -> bool:
        self._match_factor(sm, i, m.pose, m.covariance, loop=True, hess=m.hessian_covariance)
        self.loops.append((sm.anchor, i, m.score))
        self._accepted.add((sm.anchor, i))
        return True

    # -- results -------------------------------------------------------------------------------
    def trajectory(self) -> np.ndarray:
        """(N, 3) current optimised pose of every scan."""
        return self.graph.poses(len(self.front))

    def finish(self, iterations: int = 50) -> np.ndarray:
        """Batch Levenberg-Marquardt over the whole graph, then ``refine_passes`` passes of
        scan-to-scan refinement (:meth:`_scan_factors`); (N, 3) poses."""
        if not self.front:
            return np.zeros((0, 3))
        poses = self.graph.optimize_batch(iterations)
        for _ in range(self.params.refine_passes):
            poses = self.graph.optimize_with(self._scan_factors(poses), poses, iterations)
        return poses

    def _icp_polish(self, sm: Submap, m: MatchResult, local: np.ndarray) -> MatchResult:
        """With ``icp_polish``: the match's pose refined by point-to-line ICP of the scan's hits
        against the submap's hits (``scan_icp``). Why: the likelihood-field polish is biased
        where the two overlap only in part: a hit the submap has not seen yet, just past the end
        of a known wall, sits in that wall's Gaussian tail, whose gradient pulls it back along
        the wall; so every step forward is measured short, by 1 to 2.5 cm with exact data.
        Point-to-line ICP pairs such a hit with the wall's end and its normal: it is only held
        across the wall. A refinement that moves the pose more than ``icp_max_correction`` or
        finds too little overlap is not used (the correlative pose stays), nor one whose
        translation information is weaker than ``icp_min_conditioning`` times its strongest
        direction (a corridor)."""
        p = self.params
        if not p.icp_polish or len(local) < p.min_points:
            return m
        if sm.icp is None:
            sm.icp = IcpScan.build(np.concatenate(sm.points) if sm.points else np.zeros((0, 2)))
        r = icp_match(sm.icp, local, m.pose, prior_sd=(p.icp_prior_xy, p.icp_prior_theta) if p.icp_prior_xy > 0 else None)
        if r is None or r.overlap < p.refine_min_overlap:
            return m
        # A corridor: the lines fix the pose across it only; keep the correlative pose, whose
        # prior towards the odometry decides along it.
        vals = np.linalg.eigvalsh(0.5 * (r.information[:2, :2] + r.information[:2, :2].T))
        if vals[0] < p.icp_min_conditioning * vals[1]:
            return m
        moved = relative_pose(m.pose, r.pose)
        if math.hypot(moved[0], moved[1]) > p.icp_max_correction or abs(moved[2]) > math.radians(3.0):
            return m
        return attrs.evolve(m, pose=r.pose)

    def _icp_scan(self, k: int) -> IcpScan:
        scan = self._icp.get(k)
        if scan is None:
            scan = self._icp[k] = IcpScan.build(self._scans[k])
        return scan

    def _scan_factors(self, poses: np.ndarray) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
        """Scan-to-scan factors (Lu and Milios; ``scan_icp``): each node against up to
        ``refine_neighbours`` earlier nodes whose pose in ``poses`` lies within
        ``refine_radius``, nearest first, by point-to-line ICP from the relative pose the
        estimate gives; a pair whose overlap is under ``refine_min_overlap`` is dropped. A
        factor carries no submap, so the front end's poses inside a submap are not frozen into
        it. Its information is the ICP's over ``refine_cov_scale`` (the hits of one wall are not
        independent), floored by a wide Gaussian so that a corridor's unseen direction stays
        well-posed. Per node the cost is a k-d tree query and a bounded number of matches."""
        from scipy.spatial import cKDTree

        p = self.params
        pos = np.asarray(poses, dtype=np.float64)[:, :2]
        tree = cKDTree(pos)
        floor = np.diag([1.0, 1.0, 1.0 / 0.25])
        out: list[tuple[int, int, np.ndarray, np.ndarray]] = []
        for i in range(1, len(pos)):
            if len(self._scans[i]) < p.min_points:
                continue
            near = tree.query_ball_point(pos[i], p.refine_radius)
            near = [j for j in near if j < i]
            if not near:
                continue
            d = np.hypot(pos[near, 0] - pos[i, 0], pos[near, 1] - pos[i, 1])
            for j in (near[k] for k in np.argsort(d, kind="stable")[: p.refine_neighbours]):
                guess = relative_pose(poses[j], poses[i])
                r = icp_match(self._icp_scan(j), self._scans[i], guess)
                if r is None or r.overlap < p.refine_min_overlap:
                    continue
                # ICP's information is in j's axes; the factor's error is in i's.
                c, s = math.cos(r.pose[2]), math.sin(r.pose[2])
                rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
                out.append((j, i, r.pose, rot.T @ r.information @ rot / p.refine_cov_scale + floor))
        return out
