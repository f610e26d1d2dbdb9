"""Monte Carlo localization (the AMCL family), pure numpy: :class:`ParticleFilter`.

One call per laser scan, :meth:`ParticleFilter.update` with the odometry pose at the scan:

1. Motion: once the odometry moved ``update_min_d`` or turned ``update_min_a`` since the last
   sensor update, every particle is moved by a draw of the odometry motion model
   (``localization.motion``). A step larger than ``jump_distance``/``jump_angle`` between two
   consecutive calls is an odometry jump: it is reported, and each particle takes a random
   fraction of it (a slip and a real move both stay possible) so the cloud, and the covariance,
   grow instead of following the jump blindly.
2. Sensor: the likelihood field (``localization.likelihood``) scores each particle; the weights
   are multiplied by the likelihoods.
3. Every ``resample_interval`` updates, resampling: the particle count comes from KLD sampling
   (Fox 2003, as AMCL computes it: bins of 0.5 m x 0.5 m x 10 deg, bounded by
   ``min_particles``/``max_particles``); the particles are drawn by low-variance (systematic)
   resampling; with ``recovery_alpha_slow``/``recovery_alpha_fast`` set, a fraction
   ``max(0, 1 - w_fast / w_slow)`` of them is replaced by random poses in free space (Augmented
   MCL; while injecting, ``max_particles`` are drawn), so a robot whose scans stop matching (kidnapped, or a wrong initial pose) is found again.
   The averages track the per-beam geometric mean likelihood (the mean of exp(log L / beams)),
   a number between z_rand / range and z_hit that does not depend on the beam count. Unlike
   AMCL, the averages are not reset after an injection: AMCL's reset re-seeds both at the
   current, poor level, so it injects once per drop and a robot not found by that one batch
   stays lost; here injection goes on while the short-term average stays below the long-term
   one, and stops once the scans match again.

Global localization (:meth:`ParticleFilter.global_localization`) is a search until one
hypothesis (cluster) holds ``converged_weight`` on ``converged_updates`` consecutive updates
and over ``converged_travel`` metres of travel (staying where the odometry carries it): the
full ``max_particles``, the likelihood tempered with ``search_min_ess_fraction``, and each scan
the heaviest hypotheses scan-matched to their likelihood peaks and reweighted by them, each
peak less a cost for every beam that would pass through a wall from there
(``hypothesis_beta``, ``search_through_wall_nats``, see ``_search_step``), and new places proposed from the scan itself
(``search_candidates``, see ``_propose``): the uniform start often leaves no particle within
reach of the robot's place, and a search that never had the right place cannot keep it.
Then the other places' particles are dropped and the filter tracks as from a known pose.
With ``runner_up_nats`` (off by default; issue 36, measured in docs/localization.md) the
places that fitted about as well as the winner when the search ends are kept as runner-ups
that can take over later (``_runner_up_step``).

The estimate is the weighted mean of the heaviest cluster (the particles within 1 m and 0.5 rad
of the heaviest 1 m x 1 m x 45 deg bin); its covariance is the weighted spread of all particles
around it, so a cloud split between two places reports a large covariance, as it should.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Callable

import numpy as np

from emos.geometry import wrap_angle

from ..maps.grid import OccupancyGridMap
from .likelihood import LikelihoodField, select_beams
from .motion import compose_pose, relative_pose, sample_odometry_motion
from .params import AmclParams

__all__ = ["ParticleFilter", "kld_limit", "low_variance_resample"]

_KLD_BIN = (0.5, 0.5, math.radians(10.0))


def kld_limit(k: np.ndarray | int, pf_err: float, pf_z: float, min_particles: int, max_particles: int) -> np.ndarray:
    """Particles KLD sampling asks for when the samples fill ``k`` bins (AMCL's formula, with
    ``pf_z`` used as the normal quantile, as AMCL does). One bin asks for ``min_particles``
    (the formula's limit); AMCL returns ``max_particles`` there, which makes a cloud that
    converged into a single bin the most expensive one."""
    k = np.asarray(k, dtype=np.float64)
    km1 = np.maximum(k - 1.0, 1.0)
    b = 2.0 / (9.0 * km1)
    n = np.ceil(km1 / (2.0 * pf_err) * (1.0 - b + np.sqrt(b) * pf_z) ** 3)
    n = np.where(k <= 1, min_particles, n)
    return np.clip(n, min_particles, max_particles).astype(np.int64)


def low_variance_resample(weights: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of ``n`` particles drawn by systematic resampling (one random offset, then evenly
    spaced pointers into the cumulative weights): each particle with weight w is drawn
    floor(n w) or ceil(n w) times, the least random of the unbiased schemes."""
    cum = np.cumsum(weights)
    cum /= cum[-1]
    pointers = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(cum, pointers, side="right"), len(weights) - 1)


def _bins(poses: np.ndarray, size: tuple[float, float, float]) -> np.ndarray:
    """One integer key per pose for the (x, y, yaw) bin it falls in."""
    ix = np.floor(poses[:, 0] / size[0]).astype(np.int64)
    iy = np.floor(poses[:, 1] / size[1]).astype(np.int64)
    ia = np.floor(wrap_angle(poses[:, 2]) / size[2]).astype(np.int64)
    return (ix * 1_000_003 + iy) * 1_009 + ia


class _RunnerUp:
    """A hypothesis kept after the search ended (``ParticleFilter._runner_up_step``)."""

    def __init__(self, particles: np.ndarray, deficit: float, weights: np.ndarray | None = None) -> None:
        self.particles = particles
        n = len(particles)
        self.weights = np.full(n, 1.0 / n) if weights is None else weights
        self.deficit = deficit  # nats by which its peaks trail the leader's, summed (capped per scan)
        self.mean = np.zeros(3)
        self.best = np.zeros(3)
        self.peak_pose = np.zeros(3)


class ParticleFilter:
    """Monte Carlo localization against one occupancy grid (see the module docstring).

    ``sensor_pose``: (x, y, yaw) of the scanner on the robot. ``seed``: the random generator's
    seed (None: fresh entropy). ``on_problem(key, message)``: where problems with the data are
    reported (an odometry jump, a scan without one valid beam); default: a warning log.
    """

    def __init__(self, params: AmclParams, grid: OccupancyGridMap, *, sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 seed: int | None = None, on_problem: Callable[[str, str], None] | None = None) -> None:
        self.params = params
        self.sensor_pose = sensor_pose
        self.rng = np.random.default_rng(seed)
        # The runner-ups' own stream: keeping them does not change the main cloud's draws, so a
        # trial in which no runner-up takes over runs exactly as without them.
        self._runner_rng = np.random.default_rng(None if seed is None else [int(seed), 1])
        self._problem = on_problem or (lambda key, msg: logging.getLogger("emos.nav.localization").warning("%s", msg))
        self.set_map(grid)
        self.particles = np.zeros((0, 3))
        self.weights = np.zeros(0)
        self._odom_last: np.ndarray | None = None     # odometry pose of the last call
        self._odom_updated: np.ndarray | None = None  # odometry pose of the last sensor update
        self._jumped = False
        self._updates = 0
        self.w_slow = 0.0
        self.w_fast = 0.0
        self.estimate = np.zeros(3)
        self.covariance = np.diag([1e6, 1e6, 1e6])
        self.initialized = False
        self.beams_used = 0
        self.beta = 1.0
        self._injecting = False
        self.searching = False  # a global localization that has not converged yet
        self.hypothesis_shares = np.zeros(0)  # weight of each hypothesis at the last search step
        # The search's leader: the pose of the hypothesis that held converged_weight at the last
        # search step, the odometry then, and on how many consecutive steps it held it.
        self._leader: np.ndarray | None = None
        self._leader_odom: np.ndarray | None = None
        self.leader_updates = 0
        self.leader_travel = 0.0  # odometry travel (m) over which the current leader has held
        # Runner-up hypotheses kept after the search ended (``runner_up_nats``): each one's
        # particles, weights and deficit (nats by which its scan-matched peaks trail the leader's).
        self.runner_ups: list[_RunnerUp] = []
        self.switches = 0  # how many times a runner-up took over the estimate

    # -- the map and the initial state ---------------------------------------------------------------
    def set_map(self, grid: OccupancyGridMap) -> None:
        """Use ``grid`` from now on (the particles stay where they are)."""
        p = self.params
        self.field = LikelihoodField(grid, sigma_hit=p.sigma_hit, z_hit=p.z_hit, z_rand=p.z_rand,
                                     max_dist=p.laser_likelihood_max_dist, laser_max_range=self._max_range(math.inf),
                                     interpolation=p.field_interpolation)
        self.grid = grid

    def _max_range(self, scan_max: float) -> float:
        # Nav2: laser_max_range -1 (or any negative value) means the scan's own range_max.
        mx = self.params.laser_max_range
        return scan_max if mx <= 0 else mx

    def _reset_odometry(self) -> None:
        self._odom_updated = None
        self._updates = 0
        self.w_slow = self.w_fast = 0.0

    def initialize(self, pose: np.ndarray, covariance: np.ndarray | None = None) -> None:
        """Particles around ``pose`` (x, y, yaw), Gaussian with ``covariance`` (3x3; default the
        ``initial_cov_*`` parameters). A pose off the map, or a non-finite one, is a ValueError."""
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise ValueError(f"initial pose: expected finite (x, y, yaw), got {pose.tolist()}")
        cell = self.grid.world_to_grid(pose[None, :2])
        if not bool(self.grid.in_bounds(cell)[0]):
            xmin, ymin, xmax, ymax = self.grid.world_bounds()
            raise ValueError(f"initial pose ({pose[0]:.2f}, {pose[1]:.2f}) is outside the map "
                             f"[{xmin:.2f}, {xmax:.2f}] x [{ymin:.2f}, {ymax:.2f}]")
        p = self.params
        cov = np.diag([p.initial_cov_xy, p.initial_cov_xy, p.initial_cov_yaw]) if covariance is None else np.asarray(covariance, dtype=np.float64)
        if cov.shape != (3, 3) or not np.all(np.isfinite(cov)):
            raise ValueError(f"initial covariance: expected a finite 3x3 matrix, got shape {cov.shape}")
        cov = 0.5 * (cov + cov.T) + np.eye(3) * 1e-12
        try:
            chol = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            chol = np.diag(np.sqrt(np.clip(np.diag(cov), 0.0, None)))
        n = p.max_particles
        self.particles = pose + self.rng.normal(size=(n, 3)) @ chol.T
        self.particles[:, 2] = wrap_angle(self.particles[:, 2])
        self.weights = np.full(n, 1.0 / n)
        self._reset_odometry()
        self._estimate()
        self.initialized = True
        self.searching = False
        self.runner_ups = []

    def global_localization(self) -> None:
        """Particles spread uniformly over the free space of the map, any heading (ValueError if
        the map has no free cell: an unknown-only map cannot localize anyone)."""
        free = self.field.free_cells
        if len(free) == 0:
            raise ValueError("global localization: the map has no free cell (unknown or occupied only)")
        self.particles = self._random_free_poses(self.params.max_particles)
        n = len(self.particles)
        self.weights = np.full(n, 1.0 / n)
        self._reset_odometry()
        self._estimate()
        self.initialized = True
        self.searching = True
        self._leader = self._leader_odom = None
        self.leader_updates = 0
        self.leader_travel = 0.0
        self.runner_ups = []

    def _random_free_poses(self, n: int) -> np.ndarray:
        free = self.field.free_cells
        pick = free[self.rng.integers(0, len(free), n)]
        local = (pick[:, ::-1] + self.rng.random((n, 2))) * self.grid.resolution  # (col, row) -> metres
        world = self.grid.map_to_world(local)
        return np.column_stack([world, self.rng.uniform(-math.pi, math.pi, n)])

    # -- one scan ------------------------------------------------------------------------------------
    def update(self, odom_pose: np.ndarray, ranges: np.ndarray, angles: np.ndarray, *, scan_max: float = math.inf,
               scan_min: float = 0.0, force: bool = False) -> bool:
        """Feed one scan and the odometry pose at its time; True if the filter updated (moved
        enough, or ``force``). Raises ValueError on a non-finite odometry pose."""
        if not self.initialized:
            raise RuntimeError("ParticleFilter.update: set an initial pose or call global_localization first")
        odom = np.asarray(odom_pose, dtype=np.float64)
        if odom.shape != (3,) or not np.all(np.isfinite(odom)):
            raise ValueError(f"odometry pose: expected finite (x, y, yaw), got {odom.tolist()}")
        p = self.params
        if self._odom_last is not None:
            step = relative_pose(self._odom_last, odom)
            if math.hypot(step[0], step[1]) > p.jump_distance or abs(step[2]) > p.jump_angle:
                self._jumped = True
                self._problem("jump", f"odometry jumped {math.hypot(step[0], step[1]):.2f} m / {math.degrees(step[2]):.0f} deg "
                                      f"between two scans (limits {p.jump_distance:g} m / {math.degrees(p.jump_angle):.0f} deg): "
                                      "spreading the particles over the jump")
        self._odom_last = odom
        first = self._odom_updated is None
        if not first:
            assert self._odom_updated is not None  # for mypy: set whenever not first
            d = relative_pose(self._odom_updated, odom)
            if not force and not self._jumped and math.hypot(d[0], d[1]) < p.update_min_d and abs(d[2]) < p.update_min_a:
                return False
            scale = self.rng.random(len(self.particles)) if self._jumped else None
            self.particles = sample_odometry_motion(self.particles, self._odom_updated, odom,
                                                    (p.alpha1, p.alpha2, p.alpha3, p.alpha4), self.rng, scale)
            for ru in self.runner_ups:
                scale = self._runner_rng.random(len(ru.particles)) if self._jumped else None
                ru.particles = sample_odometry_motion(ru.particles, self._odom_updated, odom,
                                                      (p.alpha1, p.alpha2, p.alpha3, p.alpha4), self._runner_rng, scale)
        self._jumped = False
        self._odom_updated = odom
        max_range = self._max_range(scan_max)
        min_range = scan_min if p.laser_min_range < 0 else p.laser_min_range
        r, a = select_beams(ranges, angles, p.max_beams, min_range, max_range)
        self.beams_used = len(r)
        if len(r) == 0:
            self._problem("beams", "scan has no valid beam (all NaN, inf, zero or out of range): motion update only")
            self._estimate()
            return True
        loglik = self.field.log_likelihood(self.particles, r, a, self.sensor_pose)
        # Not while injecting: a random particle that lands on the robot must be able to win.
        min_ess = p.search_min_ess_fraction if self.searching else p.min_ess_fraction
        self.beta = 1.0 if self._injecting else self._tempering(loglik, min_ess)
        logw = np.log(np.maximum(self.weights, 1e-300)) + self.beta * loglik
        logw -= logw.max()
        w = np.exp(logw)
        self.weights = w / w.sum()
        if self.searching:
            self._search_step(loglik, *select_beams(ranges, angles, 100_000, min_range, max_range))
        # Recovery: running averages of the per-beam likelihood (see the module docstring).
        w_avg = float(np.mean(np.exp(loglik / len(r))))
        if self.w_slow == 0.0:
            self.w_slow = self.w_fast = w_avg
        else:
            self.w_slow += p.recovery_alpha_slow * (w_avg - self.w_slow)
            self.w_fast += p.recovery_alpha_fast * (w_avg - self.w_fast)
        self._estimate()
        if p.refine_estimate:
            # Every valid beam: the search scores 27 poses a round, not thousands.
            self._refine(*select_beams(ranges, angles, 100_000, min_range, max_range))
        if self.runner_ups:
            self._runner_up_step(loglik, r, a, *select_beams(ranges, angles, 100_000, min_range, max_range))
        self._updates += 1
        if self._updates % p.resample_interval == 0:
            self._resample()
        return True

    def _tempering(self, loglik: np.ndarray, min_ess_fraction: float, weights: np.ndarray | None = None) -> float:
        """The exponent (0, 1] on this scan's likelihood that keeps the effective sample size
        at ``min_ess_fraction`` of the particles at least (1 when the full likelihood does).
        Beams are not independent (neighbours see the same wall), so their product overstates
        the evidence; with a poor prior (global localization, a kidnapping, a jump) it would
        put all the weight on whichever particle happens to sit nearest, and resampling would
        keep only that one. Tempered, the cloud narrows over a few scans instead of one."""
        target = min_ess_fraction * len(loglik)
        if target <= 1.0:
            return 1.0
        logw0 = np.log(np.maximum(self.weights if weights is None else weights, 1e-300))
        centred = loglik - loglik.max()

        def ess(beta: float) -> float:
            lw = logw0 + beta * centred
            w = np.exp(lw - lw.max())
            return float(w.sum() ** 2 / (w @ w))

        if ess(1.0) >= target:
            return 1.0
        lo, hi = 0.0, 1.0
        for _ in range(20):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if ess(mid) >= target else (lo, mid)
        return max(lo, 1e-6)

    def _resample(self) -> None:
        p = self.params
        # KLD: the count at which the drawn samples' bins stop asking for more. Draw max_particles
        # in a random order, count the bins the first n fill, take the first n that is enough.
        cand = self.particles[low_variance_resample(self.weights, p.max_particles, self.rng)]
        cand = cand[self.rng.permutation(len(cand))]
        keys = _bins(cand, _KLD_BIN)
        _, first = np.unique(keys, return_index=True)
        new_bin = np.zeros(len(cand), dtype=np.int64)
        new_bin[first] = 1
        k = np.cumsum(new_bin)
        limits = kld_limit(k, p.pf_err, p.pf_z, p.min_particles, p.max_particles)
        enough = np.flatnonzero(np.arange(1, len(cand) + 1) >= limits)
        n = int(enough[0] + 1) if len(enough) else p.max_particles
        n = max(min(n, p.max_particles), p.min_particles)
        w_diff = 0.0 if self.w_slow <= 0 or p.recovery_alpha_slow == 0 or p.recovery_alpha_fast == 0 else max(0.0, 1.0 - self.w_fast / self.w_slow)
        self._injecting = w_diff > 0
        if w_diff > 0 or self.searching:
            n = p.max_particles  # searching: the whole budget, so the random share has a chance to land near
        out = self.particles[low_variance_resample(self.weights, n, self.rng)]
        if w_diff > 0 and len(self.field.free_cells):
            inject = self.rng.random(n) < w_diff
            if inject.any():
                out[inject] = self._random_free_poses(int(inject.sum()))
        self.particles = out
        self.weights = np.full(n, 1.0 / n)

    # -- global localization: the hypotheses -------------------------------------------------------
    def _hypotheses(self, k_max: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The ``k_max`` heaviest hypotheses, greedily: the heaviest 1 m x 1 m x 45 deg bin of the
        particles not taken yet, and every such particle within 1 m and 0.5 rad of its weighted
        mean (as the estimate's cluster). Returns each particle's hypothesis (-1: none), each
        hypothesis's weight and each one's weighted mean pose (k, 3)."""
        parts, w = self.particles, self.weights
        labels = np.full(len(parts), -1, dtype=np.int64)
        free = np.arange(len(parts))
        shares, means = [], []
        # The bins once (one sort), then each round's heaviest bin among the particles not taken.
        _, bin_of = np.unique(_bins(parts, (1.0, 1.0, math.radians(45.0))), return_inverse=True)
        bin_of = bin_of.reshape(-1)
        for k in range(k_max):
            if len(free) == 0:
                break
            sub, sw, inv = parts[free], w[free], bin_of[free]
            heaviest = inv == np.bincount(inv, weights=sw).argmax()
            centre = self._weighted_mean(sub[heaviest], sw[heaviest])
            d = sub[:, :2] - centre[:2]
            near = heaviest | ((np.einsum("ij,ij->i", d, d) <= 1.0) & (np.abs(wrap_angle(sub[:, 2] - centre[2])) <= 0.5))
            labels[free[near]] = k
            shares.append(float(sw[near].sum()))
            means.append(self._weighted_mean(sub[near], sw[near]))
            free = free[~near]
        return labels, np.array(shares), np.array(means).reshape(-1, 3)

    def _search_step(self, loglik: np.ndarray, ranges: np.ndarray, angles: np.ndarray) -> None:
        """One scan of a global localization: weigh the heaviest hypotheses against each other by
        their scan-matched peaks (``hypothesis_beta``), then end the search once one of them holds
        ``converged_weight``. The tempered particle weights say little about which of two
        well-separated places fits better (tempering keeps a few percent of each scan's evidence,
        so that the cloud does not collapse on the one particle nearest by chance), and each
        place's particles sample its likelihood too coarsely to compare them directly: a
        particle 10 cm off the peak loses as much as a wrong place. Matched to their peaks, the
        places compare on the scan itself."""
        p = self.params
        labels, shares, means = self._hypotheses(p.max_hypotheses)
        best_peak: float | None = None
        peaks: np.ndarray | None = None
        compare = p.hypothesis_beta > 0 and len(shares) > 1
        if (compare or p.search_candidates > 0) and len(shares) > 0 and len(ranges) > 0:
            # Two starts per hypothesis: its weighted mean and its best particle on this scan.
            k = len(shares)
            taken = labels >= 0
            best = np.full(k, -1, dtype=np.int64)
            order = np.flatnonzero(taken)[np.argsort(loglik[taken], kind="stable")]
            best[labels[order]] = order  # the last write per hypothesis is its best particle
            starts = np.vstack([means, self.particles[best]])
            peaks = self._search_peaks(starts, ranges, angles)[1].reshape(2, k).max(axis=0)
            best_peak = float(peaks.max())
            if compare:
                factor = np.exp(p.hypothesis_beta * (peaks - best_peak))
                w = self.weights * np.where(taken, factor[np.maximum(labels, 0)], 1.0)
                self.weights = w / w.sum()
                shares = np.bincount(labels[taken], weights=self.weights[taken], minlength=k)
        self.hypothesis_shares = shares
        if not self._leader_holds(shares, means, p):
            if best_peak is not None:
                self._propose(means, best_peak, ranges, angles)
            return
        self.searching = False
        lead = int(shares.argmax())
        if peaks is not None and p.runner_up_nats > 0:
            self._keep_runner_ups(labels, shares, peaks, lead)
        # Drop the other places' leftovers: untempered from the next scan on, one stray
        # particle elsewhere that happens to fit can take all the weight from a cloud that
        # is still decimetres wide (seen on intel).
        w = np.where(labels == lead, self.weights, 0.0)
        self.weights = w / w.sum()

    def _propose(self, means: np.ndarray, best_peak: float, ranges: np.ndarray, angles: np.ndarray) -> None:
        """Mixture proposal while searching: look for places the particles do not cover yet.
        ``search_candidates`` random poses in free space are scored on a subset of the scan's
        beams (about 30), the ``search_climbs`` best are scan-matched to their nearest likelihood
        peak (every valid beam, as the hypotheses are), and each peak that is not one of the
        listed hypotheses and fits within about 23 nats (a factor 0.01 at ``hypothesis_beta``)
        of the best hypothesis's peak becomes a particle, replacing the lightest ones. Together
        they get at most ``search_inject_share`` of the weight, each in proportion to
        ``exp(hypothesis_beta * (its peak - the best peak))`` (capped at 1): a place that fits
        better than every hypothesis enters as a runner-up, and the next scans' peak comparison
        decides. Why: the uniform start puts one or two particles within the likelihood
        peak's reach (0.3 m, 8 deg) of the robot on the Radish maps, often none; such a trial
        never had the right place to keep (intel seeds 53 and 54, csail seed 53: the logged pose
        fits the scan better than where the search ended, and no particle was near it from the
        third scan on). Each scan's new candidates are another draw of that lottery, and a
        candidate only has to land within the peak's reach, not on it."""
        p = self.params
        if p.search_candidates <= 0 or len(self.field.free_cells) == 0:
            return
        cand = self._random_free_poses(p.search_candidates)
        step = max(1, len(ranges) // 30)
        score = self.field.log_likelihood(cand, ranges[::step], angles[::step], self.sensor_pose)
        top = np.argsort(score)[-p.search_climbs:]
        poses, peaks = self._search_peaks(cand[top], ranges, angles)
        beta = max(p.hypothesis_beta, 1e-3)
        f = np.minimum(1.0, np.exp(beta * (peaks - best_peak)))
        keep = f >= 0.01
        if len(means):
            d = np.hypot(poses[:, None, 0] - means[None, :, 0], poses[:, None, 1] - means[None, :, 1])
            covered = (d <= 0.5) & (np.abs(wrap_angle(poses[:, None, 2] - means[None, :, 2])) <= 0.3)
            keep &= ~covered.any(axis=1)
        if not keep.any():
            return
        poses, f = poses[keep], f[keep]
        total = p.search_inject_share * min(1.0, float(f.sum()))
        slots = np.argsort(self.weights, kind="stable")[: len(poses)]
        w = self.weights.copy()
        w[slots] = 0.0
        w *= (1.0 - total) / w.sum()
        w[slots] = total * f / f.sum()
        self.particles[slots] = poses
        self.weights = w

    # -- after the search: runner-up hypotheses ---------------------------------------------------
    def _keep_runner_ups(self, labels: np.ndarray, shares: np.ndarray, peaks: np.ndarray, lead: int) -> None:
        """At the end of a search: keep each other hypothesis whose scan-matched peak on this
        scan is within ``runner_up_nats`` of the leader's (any of the search's listed hypotheses,
        the heaviest first) as a runner-up of ``runner_up_particles`` particles, drawn from its
        own particles by their weights. Its deficit starts at the leader's peak minus its own
        (capped at ``runner_up_scan_nats``)."""
        p = self.params
        for h in np.argsort(-shares, kind="stable"):
            h = int(h)
            if h == lead or shares[h] <= 0.0 or peaks[h] < peaks[lead] - p.runner_up_nats:
                continue
            mine = np.flatnonzero(labels == h)
            w = self.weights[mine]
            if w.sum() <= 0.0:
                continue
            pick = mine[low_variance_resample(w / w.sum(), p.runner_up_particles, self._runner_rng)]
            deficit = float(np.clip(peaks[lead] - peaks[h], -p.runner_up_scan_nats, p.runner_up_scan_nats))
            self.runner_ups.append(_RunnerUp(self.particles[pick].copy(), deficit))

    def _runner_up_step(self, main_ll: np.ndarray, r: np.ndarray, a: np.ndarray, ranges: np.ndarray,
                        angles: np.ndarray) -> None:
        """One scan with runner-ups (``runner_up_nats``): each runner-up's particles are weighed
        on the scan (tempered to keep half of them effective) and resampled; then the leader
        (the estimate and the main cloud's best particle) and each runner-up (its mean and best
        particle) are scan-matched to their peaks on every valid beam, and each runner-up's
        deficit grows by the leader's peak minus its own, capped at ``runner_up_scan_nats`` either
        way (one odd scan, a person in front of the scanner or a scan taken mid-turn, does not
        decide). A runner-up whose deficit exceeds ``runner_up_nats`` is dropped, one whose peak
        is the leader's place (0.5 m, 0.5 rad) is merged into it, and one that leads by
        ``runner_up_switch_nats`` takes over: its particles become the filter's, the old leader
        becomes a runner-up. ``main_ll``: the main cloud's log-likelihoods on this scan (``r``,
        ``a``: the beams they used; ``ranges``, ``angles``: every valid beam)."""
        p = self.params
        if len(ranges) == 0:
            return
        for ru in self.runner_ups:
            ll = self.field.log_likelihood(ru.particles, r, a, self.sensor_pose)
            beta = self._tempering(ll, 0.5, ru.weights)
            lw = np.log(np.maximum(ru.weights, 1e-300)) + beta * ll
            w = np.exp(lw - lw.max())
            ru.weights = w / w.sum()
            ru.best = ru.particles[int(np.argmax(ll))].copy()
            ru.mean = self._weighted_mean(ru.particles, ru.weights)
        main_best = self.particles[int(np.argmax(main_ll))] if len(main_ll) else self.estimate
        starts = np.vstack([[self.estimate, main_best]] + [[ru.mean, ru.best] for ru in self.runner_ups])
        poses, values = self._climb(starts, ranges, angles)
        pick = values.reshape(-1, 2).argmax(axis=1)
        peak_pose = poses.reshape(-1, 2, 3)[np.arange(len(pick)), pick]
        peak = values.reshape(-1, 2).max(axis=1)
        lead_pose, lead_peak = peak_pose[0], float(peak[0])
        kept: list[_RunnerUp] = []
        for i, ru in enumerate(self.runner_ups, start=1):
            ru.deficit += float(np.clip(lead_peak - peak[i], -p.runner_up_scan_nats, p.runner_up_scan_nats))
            ru.peak_pose = peak_pose[i]
            same = (math.hypot(*(peak_pose[i][:2] - lead_pose[:2])) <= 0.5
                    and abs(float(wrap_angle(float(peak_pose[i][2] - lead_pose[2])))) <= 0.5)
            if ru.deficit <= p.runner_up_nats and not same:
                kept.append(ru)
            else:
                continue
            # the runner-up's particles are resampled (uniform weights) for the next scan
            idx = low_variance_resample(ru.weights, p.runner_up_particles, self._runner_rng)
            ru.particles, ru.weights = ru.particles[idx], np.full(p.runner_up_particles, 1.0 / p.runner_up_particles)
        self.runner_ups = kept
        if not kept:
            return
        best = min(kept, key=lambda ru: ru.deficit)
        if best.deficit > -p.runner_up_switch_nats:
            return
        # The runner-up takes over: its cloud becomes the filter's, the leader becomes a runner-up.
        n = p.runner_up_particles
        old = _RunnerUp(self.particles[low_variance_resample(self.weights, n, self._runner_rng)], -best.deficit)
        self.particles, self.weights = best.particles.copy(), best.weights.copy()
        self.runner_ups = [_RunnerUp(ru.particles, ru.deficit - best.deficit, ru.weights) for ru in kept if ru is not best] + [old]
        self.switches += 1
        self._estimate()
        if p.refine_estimate:
            self._refine(ranges, angles)

    def _leader_holds(self, shares: np.ndarray, means: np.ndarray, p: AmclParams) -> bool:
        """True once one hypothesis has held ``converged_weight`` on ``converged_updates``
        consecutive search steps and over ``converged_travel`` metres of odometry travel,
        staying where the odometry carries it (within 0.5 m and 0.5 rad of its last pose moved
        by the odometry since). Meant for a look-alike place (a corridor, a room repeated along
        a building) that takes 95 % of the weight on one view and would lose it on a later one.
        ``converged_travel`` is 2 m by default since the proposals (``_propose``): while the
        search runs they keep bringing in places the particles missed, so a leader that is
        wrong can still be overtaken over those 2 m (intel seed 53 from seed range 50-69:
        the search had ended on a wrong place at 4 m; with proposals and 2 m it found the
        robot at 11 m; without proposals, 1-2 m only delayed the same wrong end).
        Travel, not a count of updates: a robot turning on the spot gives an update every
        ``update_min_a`` of turn, each a view from the same place, so a count can be reached
        without new evidence (intel seed 28 ends its search on a place 15 m off after 0.47 m of
        travel, mostly turning); only driving shows the scanner new walls. ``converged_updates``
        is 1 by default: 3 was measured on 50 seeds per tuning log and did not help. Without
        proposals, ``converged_travel`` 1 m and 2 m on intel seed 28 ended the search later on
        the same wrong place (the right one had no particles left by then, see ``AmclParams``)."""
        if not len(shares) or shares.max() < p.converged_weight:
            self._leader = None
            self.leader_updates = 0
            self.leader_travel = 0.0
            return False
        lead = means[int(shares.argmax())]
        odom = self._odom_updated
        same = False
        step = 0.0
        if self._leader is not None and odom is not None and self._leader_odom is not None:
            d = relative_pose(self._leader_odom, odom)
            moved = compose_pose(self._leader, d)
            same = (math.hypot(*(lead[:2] - moved[:2])) <= 0.5
                    and abs(float(wrap_angle(float(lead[2] - moved[2])))) <= 0.5)
            step = math.hypot(float(d[0]), float(d[1]))
        self.leader_updates = self.leader_updates + 1 if same else 1
        self.leader_travel = self.leader_travel + step if same else 0.0
        self._leader, self._leader_odom = lead.copy(), None if odom is None else odom.copy()
        return self.leader_updates >= p.converged_updates and self.leader_travel >= p.converged_travel

    def _search_peaks(self, starts: np.ndarray, ranges: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The search's measure of a place: ``_climb`` to the nearest peak, less
        ``search_through_wall_nats`` for each beam that passes through a wall from there."""
        p = self.params
        poses, values = self._climb(starts, ranges, angles)
        if p.search_through_wall_nats > 0:
            values = values - p.search_through_wall_nats * self.field.through_walls(
                poses, ranges, angles, self.sensor_pose, p.search_through_wall_margin)
        return poses, values

    def _peaks(self, starts: np.ndarray, ranges: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """The log-likelihood of the scan at the nearest peak from each of ``starts`` (m, 3): a
        coarse-to-fine pattern search as ``_refine``'s, all starts at once, steps halving from
        8 cm / 2 deg to 5 mm / 0.125 deg (reach about 0.3 m and 8 deg)."""
        return self._climb(starts, ranges, angles)[1]

    def _climb(self, starts: np.ndarray, ranges: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``_peaks`` with the peaks' poses: (poses (m, 3), log-likelihoods (m,))."""
        best = starts.copy()
        value = self.field.log_likelihood(best, ranges, angles, self.sensor_pose)
        steps = np.array([-1.0, 0.0, 1.0])
        grid = np.stack(np.meshgrid(steps, steps, steps, indexing="ij"), axis=-1).reshape(-1, 3)
        dxy, dth = 0.08, math.radians(2.0)
        rows = np.arange(len(best))
        for _ in range(5):
            for _ in range(3):
                cand = best[:, None, :] + grid[None, :, :] * np.array([dxy, dxy, dth])
                values = self.field.log_likelihood(cand.reshape(-1, 3), ranges, angles, self.sensor_pose).reshape(len(best), -1)
                i = values.argmax(axis=1)
                better = values[rows, i] > value + 1e-9
                if not better.any():
                    break
                best[better] = cand[rows[better], i[better]]
                value[better] = values[rows[better], i[better]]
            dxy, dth = dxy / 2.0, dth / 2.0
        best[:, 2] = wrap_angle(best[:, 2])
        return best, np.asarray(value)

    # -- the estimate --------------------------------------------------------------------------------
    def _estimate(self) -> None:
        parts, w = self.particles, self.weights
        keys = _bins(parts, (1.0, 1.0, math.radians(45.0)))
        uniq, inv = np.unique(keys, return_inverse=True)
        best = np.bincount(inv, weights=w, minlength=len(uniq)).argmax()
        seed = inv == best
        centre = self._weighted_mean(parts[seed], w[seed])
        d = parts[:, :2] - centre[:2]
        near = (np.einsum("ij,ij->i", d, d) <= 1.0) & (np.abs(wrap_angle(parts[:, 2] - centre[2])) <= 0.5)
        self.estimate = self._weighted_mean(parts[near], w[near])
        diff = parts - self.estimate
        diff[:, 2] = wrap_angle(diff[:, 2])
        wn = w / w.sum()
        self.covariance = (diff * wn[:, None]).T @ diff

    def _refine(self, ranges: np.ndarray, angles: np.ndarray) -> None:
        """Polish the estimate to the nearest peak of the scan's likelihood (every valid beam):
        a coarse-to-fine pattern search, 27 poses a round, steps halving from 4 cm / 1 deg to
        5 mm / 0.125 deg, a step taken only when it raises the likelihood. The particles sample
        the posterior only as densely as their count allows (2000 over 0.3 m x 10 deg leave
        centimetres and degrees between neighbours); the search finds the peak between them.
        The particles are left as they are. (Adding the predicted cloud as a Gaussian prior
        to the search was tried: it made the Radish tracking errors worse, not better.)"""

        def score(poses: np.ndarray) -> np.ndarray:
            return self.field.log_likelihood(poses, ranges, angles, self.sensor_pose)

        best = self.estimate.copy()
        value = float(score(best[None, :])[0])
        steps = np.array([-1.0, 0.0, 1.0])
        grid = np.stack(np.meshgrid(steps, steps, steps, indexing="ij"), axis=-1).reshape(-1, 3)
        dxy, dth = 0.04, math.radians(1.0)
        for _ in range(4):
            for _ in range(3):  # move while it improves, at most 3 times per step size
                cand = best + grid * np.array([dxy, dxy, dth])
                values = score(cand)
                i = int(values.argmax())
                if values[i] <= value + 1e-9:
                    break
                best, value = cand[i], float(values[i])
            dxy, dth = dxy / 2.0, dth / 2.0
        best[2] = float(wrap_angle(float(best[2])))
        self.estimate = best

    @staticmethod
    def _weighted_mean(parts: np.ndarray, w: np.ndarray) -> np.ndarray:
        total = w.sum()
        wn = w / total if total > 0 else np.full(len(w), 1.0 / len(w))
        yaw = math.atan2(float(wn @ np.sin(parts[:, 2])), float(wn @ np.cos(parts[:, 2])))
        return np.array([float(wn @ parts[:, 0]), float(wn @ parts[:, 1]), yaw])

    @property
    def particle_count(self) -> int:
        return len(self.particles)
