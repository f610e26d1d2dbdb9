"""Passage guard: do not enter the stretch of the path where people walk while one is coming.

A reactive give-way cannot clear a person walking a narrow passage at 0.6 m/s: there is no
side to pull aside to and a robot backing at 0.4 m/s is caught. The robot has to wait *outside*
the people's way and go through when it can be out again before a person arrives. Two parts:

* :class:`MoverMemory`: where moving obstacles have walked (their tracked centres over the last
  ``memory`` s, a decaying record of the scan tracker's movers: never ground truth) -- the
  *band* -- and how each walked on from where it was: a mover seen again where (and heading the
  way) one walked before is predicted to walk on as that one did (a person who turned at the end
  of a corridor turns there again: the learned-motion-pattern prediction of Bennewitz et al.),
  besides at constant velocity. Both predictions count.
* :func:`check_passage`: the *stretch* of the robot's path ahead that lies in the band (within
  ``band_clearance`` of a remembered mover centre: the robot's and a person's radii plus a
  margin). The robot is held before the stretch when it cannot drive through it (at ``speed``
  after ``start_delay``, plus ``exit_margin``) without coming within ``margin`` (growing by
  ``margin_rate`` per second of prediction) of a mover's predicted position.

The Behaviors component (``BehaviorsConfig.passage_guard``) runs the check on every step and
holds the robot on its command input (above the Controller's) while it says so.
"""
from __future__ import annotations

import math

import attrs
import numpy as np

from emos.config import validators as V

__all__ = ["MoverMemory", "PassageGuardConfig", "PassageVerdict", "check_passage"]


@attrs.define(frozen=True)
class PassageGuardConfig:
    """When the robot waits before the people's way (see the module doc).

    ``band_clearance`` (m): a path point this near a remembered mover centre is in the band
    (robot radius + person radius + a margin). ``approach`` (m): the robot is held when the
    stretch begins within this distance ahead along the path. ``look_ahead`` (m of path
    checked). ``rejoin`` (m): band stretches of the path less than this apart are one stretch.
    ``speed`` (m/s the robot is assumed to drive the stretch at), ``start_delay`` (s
    before it moves), ``exit_margin`` (m past the stretch it must reach). ``margin`` (m kept
    from a predicted mover; ``margin_rate`` m more per s of prediction). ``max_hold`` (s): a hold
    longer than this gives up and lets the robot go (a mover that stays is the Controller's and
    the give-way's). ``out_of_view`` (s): with no mover in view, the one last seen this recently
    is predicted as earlier walks from where it was went on (it walked out of the scan's view,
    e.g. behind a wall, and comes back). ``memory`` (s a mover's walk is remembered), ``match_distance`` (m) and
    ``match_heading`` (rad): how near and how alike in heading an earlier walk must be to
    predict from it."""

    enabled: bool = attrs.field(default=False, validator=attrs.validators.instance_of(bool))
    band_clearance: float = attrs.field(default=0.55, validator=V.number(gt=0, le=5, finite=True, what="metres"))
    approach: float = attrs.field(default=0.6, validator=V.number(ge=0, le=5, finite=True, what="metres"))
    rejoin: float = attrs.field(default=1.0, validator=V.number(ge=0, le=10, finite=True, what="metres"))
    look_ahead: float = attrs.field(default=6.0, validator=V.number(gt=0, le=50, finite=True, what="metres"))
    speed: float = attrs.field(default=0.4, validator=V.number(gt=0, le=5, finite=True, what="m/s"))
    start_delay: float = attrs.field(default=1.0, validator=V.number(ge=0, le=10, finite=True, what="seconds"))
    exit_margin: float = attrs.field(default=0.3, validator=V.number(ge=0, le=5, finite=True, what="metres"))
    margin: float = attrs.field(default=0.15, validator=V.number(ge=0, le=3, finite=True, what="metres"))
    margin_rate: float = attrs.field(default=0.02, validator=V.number(ge=0, le=1, finite=True, what="m/s"))
    max_hold: float = attrs.field(default=60.0, validator=V.number(gt=0, le=3600, finite=True, what="seconds"))
    out_of_view: float = attrs.field(default=15.0, validator=V.number(ge=0, le=600, finite=True, what="seconds"))
    memory: float = attrs.field(default=180.0, validator=V.number(gt=0, le=86400, finite=True, what="seconds"))
    match_distance: float = attrs.field(default=0.35, validator=V.number(gt=0, le=5, finite=True, what="metres"))
    match_heading: float = attrs.field(default=math.radians(40.0), validator=V.number(gt=0, le=math.pi, finite=True, what="radians"))


@attrs.define(frozen=True)
class PassageVerdict:
    """``hold``: wait before the stretch now; ``reason`` says why (or why not); ``start``,
    ``end``: the stretch's arc lengths along the path ahead (m; None when no stretch ahead)."""

    hold: bool
    reason: str
    start: float | None = None
    end: float | None = None


SAMPLE_PERIOD = 0.1  # s between the remembered samples of one mover
MIN_SPEED = 0.3  # m/s: slower tracks are not remembered as walking (people walk 0.5 to 1.5 m/s; clutter a
# moving robot's scan makes look moving is mostly slower)
CLOCK_BACK = 1.0  # s: a sample this much older than the last one means the clock went back
GAP_LIMIT = 0.6  # s: a longer gap in the record ends a remembered walk (the mover was not seen)
MATCH_AGE = 2.0  # s: a walk is predicted from one at least this old (not the walk going on)
LEADS = (0.0, -0.5, 0.5, 1.0)  # s: the earlier walk is followed this much ahead (timing uncertainty of a track)
MAX_PASSES = 4  # earlier passes tried, most recent first (the guard runs at the component's rate)
MAX_MOVER_SPEED = 1.5  # m/s: a mover farther from the robot's drive than this covers is not checked
GHOST_RADIUS = 0.25  # m: the radius of a mover out of view (a person)
OUT_OF_VIEW_AFTER = 0.5  # s: a mover not recorded walking for longer is out of view (or stopped)


class MoverMemory:
    """Where movers walked (world frame) for ``memory`` s: samples (t, x, y, vx, vy) of the
    moving tracks, at most one per ``SAMPLE_PERIOD`` per mover."""

    def __init__(self, memory: float = 180.0) -> None:
        self.memory = float(memory)
        self._rows: list[tuple[float, float, float, float, float]] = []
        self._array: np.ndarray | None = None
        self._cells: np.ndarray | None = None  # band_cells, until the next sample
        self._last_t = -math.inf

    def observe(self, t: float, centres: np.ndarray, velocities: np.ndarray) -> None:
        """Record the moving tracks seen at ``t`` s: ``centres`` and ``velocities`` (M, 2)."""
        t = float(t)
        if t < self._last_t - CLOCK_BACK and self._rows:
            # The clock went back (a restarted simulator starts its clock again): the band stays,
            # the record is moved to end just before now, its walks' timing kept.
            shift = t - SAMPLE_PERIOD - self._last_t
            self._rows = [(r[0] + shift, *r[1:]) for r in self._rows]
            self._last_t += shift
            self._array = None
        if t < self._last_t + SAMPLE_PERIOD:
            return
        centres = np.asarray(centres, dtype=float).reshape(-1, 2)
        velocities = np.asarray(velocities, dtype=float).reshape(-1, 2)
        fast = np.hypot(velocities[:, 0], velocities[:, 1]) >= MIN_SPEED
        if not fast.any():
            return
        self._last_t = t
        self._rows.extend((t, float(c[0]), float(c[1]), float(v[0]), float(v[1])) for c, v in zip(centres[fast], velocities[fast]))
        cut = t - self.memory
        if self._rows[0][0] < cut:
            self._rows = [r for r in self._rows if r[0] >= cut]
        self._array = self._cells = None

    def samples(self) -> np.ndarray:
        """(N, 5) rows (t, x, y, vx, vy), oldest first."""
        if self._array is None:
            self._array = np.array(self._rows, dtype=float).reshape(-1, 5)
        return self._array

    def band_cells(self) -> np.ndarray:
        """(K, 2) centres of the 5 cm cells where movers walked: the band, not every sample (a
        person walking a corridor for minutes)."""
        if self._cells is None:
            rows = self.samples()
            self._cells = (np.unique(np.round(rows[:, 1:3] / 0.05).astype(np.int64), axis=0) * 0.05 if len(rows)
                           else np.zeros((0, 2)))
        return self._cells

    def band_gap(self, points: np.ndarray) -> np.ndarray:
        """(N,) distance from each point (N, 2) to the nearest remembered mover centre (inf: none)."""
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        cells = self.band_cells()
        if len(cells) == 0 or len(pts) == 0:
            return np.full(len(pts), np.inf)
        d = np.hypot(pts[:, None, 0] - cells[None, :, 0], pts[:, None, 1] - cells[None, :, 1])
        out: np.ndarray = d.min(axis=1)
        return out

    def _walk_from(self, k: int, horizon: float) -> tuple[list[float], list[np.ndarray], np.ndarray]:
        """The record of the walk through sample ``k`` from then on, while unbroken and at most
        ``horizon`` s: times from then, centres, and the last sample (several movers: the
        sample nearest the last one per time step)."""
        rows = self.samples()
        t0 = rows[k, 0]
        stop = int(np.searchsorted(rows[:, 0], t0 + horizon + SAMPLE_PERIOD, side="right"))
        seg = rows[k:stop]
        if len(seg) and np.all(np.diff(seg[:, 0]) > 0):  # one mover recorded at a time: vectorized
            gaps = np.flatnonzero(np.diff(seg[:, 0]) > GAP_LIMIT)
            seg = seg[:int(gaps[0]) + 1] if len(gaps) else seg
            jumps = np.flatnonzero(np.hypot(*np.diff(seg[:, 1:3], axis=0).T) > 3.0 * np.diff(seg[:, 0]) + 0.1)
            seg = seg[:int(jumps[0]) + 1] if len(jumps) else seg  # another mover: the walk's record ends
            return list(seg[:, 0] - t0), list(seg[:, 1:3]), seg[-1]
        walk_t, walk_xy = [0.0], [rows[k, 1:3]]
        j, last = k + 1, rows[k]
        while j < len(rows) and rows[j, 0] - t0 <= horizon + SAMPLE_PERIOD:
            if rows[j, 0] - last[0] > GAP_LIMIT:
                break
            group = rows[j:int(np.searchsorted(rows[:, 0], rows[j, 0], side="right"))]
            i = int(np.argmin(np.hypot(group[:, 1] - last[1], group[:, 2] - last[2])))
            if math.hypot(group[i, 1] - last[1], group[i, 2] - last[2]) <= 3.0 * (rows[j, 0] - last[0]) + 0.1:
                last = group[i]
                walk_t.append(float(last[0] - t0))
                walk_xy.append(last[1:3])
            j += len(group)
        return walk_t, walk_xy, last

    def last_seen(self) -> np.ndarray:
        """(K, 5) rows of the latest time a mover was recorded (one per mover seen then)."""
        rows = self.samples()
        return rows[rows[:, 0] == rows[-1, 0]] if len(rows) else rows

    def predict(self, now: float, centre: np.ndarray, velocity: np.ndarray, times: np.ndarray, *,
                match_distance: float = 0.35, match_heading: float = math.radians(40.0),
                learned_only: bool = False) -> list[np.ndarray]:
        """Predicted centres (len(times), 2) of a mover at ``centre`` with ``velocity`` now, at
        ``times`` s from now: at constant velocity, and, when an earlier walk passed here the
        same way, as that walk went on (until the record of it ends; then at its last velocity).
        ``learned_only``: only the earlier walk, and NaN past its record (a mover out of view:
        where it went is unknown but for what movers did before)."""
        c = np.asarray(centre, dtype=float)
        v = np.asarray(velocity, dtype=float)
        times = np.asarray(times, dtype=float)
        out = [] if learned_only else [c[None, :] + v[None, :] * times[:, None]]
        rows = self.samples()
        speed = float(np.hypot(*v))
        if len(rows) == 0 or speed < MIN_SPEED:
            return out
        old = rows[:, 0] <= now - MATCH_AGE
        near = np.hypot(rows[:, 1] - c[0], rows[:, 2] - c[1]) <= match_distance
        rs = np.hypot(rows[:, 3], rows[:, 4])
        cos = (rows[:, 3] * v[0] + rows[:, 4] * v[1]) / np.maximum(rs * speed, 1e-9)
        match = np.flatnonzero(old & near & (cos >= math.cos(match_heading)))
        if len(match) == 0:
            return out
        horizon = (float(times[-1]) if len(times) else 0.0) + max(LEADS)
        # The most recent earlier walk through here whose record covers the horizon (the mover
        # was not always in view), else the one recorded longest.
        # One pass by here: matches less than a second apart; of each, the sample nearest the mover.
        passes = np.split(match, np.flatnonzero(np.diff(rows[match, 0]) > 1.0) + 1)
        best: tuple[list[float], list[np.ndarray], np.ndarray] | None = None
        for group in passes[::-1][:MAX_PASSES]:
            k = int(group[np.argmin(np.hypot(rows[group, 1] - c[0], rows[group, 2] - c[1]))])
            walk = self._walk_from(k, horizon)
            if best is None or walk[0][-1] > best[0][-1]:
                best = walk
            if best[0][-1] >= horizon:
                break
        assert best is not None
        walk_t, walk_xy, last = best
        if len(walk_t) < 2:
            return out
        wt, wxy = np.array(walk_t), np.array(walk_xy)
        shift = c - wxy[0]  # the walk as it went, from where the mover is now
        # The track's velocity lags its walk (a fit over the last second): near a turn it still
        # says "down" when the person walks up again. The walk is also taken a little earlier
        # and later (LEADS s), each a hypothesis.
        for lead in LEADS:
            at = np.maximum(times + lead, 0.0)
            pred = np.c_[np.interp(at, wt, wxy[:, 0]), np.interp(at, wt, wxy[:, 1])] + shift
            beyond = at > wt[-1]
            if beyond.any():  # past the record: on at the walk's last velocity (unknown for a mover out of view)
                pred[beyond] = np.nan if learned_only else wxy[-1] + shift + last[3:5] * (at[beyond] - wt[-1])[:, None]
            out.append(pred)
        return out


def _arc_lengths(path: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])


def path_ahead(path: np.ndarray, robot_xy: np.ndarray, look_ahead: float) -> np.ndarray:
    """The part of ``path`` (N, >=2) from the point nearest the robot on, at most ``look_ahead``
    m long, starting at the robot: (K, 2)."""
    xy = np.asarray(path, dtype=float)[:, :2]
    if len(xy) == 0:
        return np.asarray(robot_xy, dtype=float)[None, :2]
    k = int(np.argmin(np.hypot(xy[:, 0] - robot_xy[0], xy[:, 1] - robot_xy[1])))
    ahead = np.vstack([np.asarray(robot_xy, dtype=float)[None, :2], xy[k:]])
    s = _arc_lengths(ahead)
    return ahead[s <= look_ahead] if (s <= look_ahead).sum() >= 2 else ahead[:2]


def _resample(path: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    s = _arc_lengths(path)
    grid = np.arange(0.0, s[-1] + 1e-9, step) if s[-1] > 0 else np.zeros(1)
    return np.c_[np.interp(grid, s, path[:, 0]), np.interp(grid, s, path[:, 1])], grid


def check_passage(path: np.ndarray, robot_xy: np.ndarray, memory: MoverMemory, now: float, centres: np.ndarray,
                  velocities: np.ndarray, radii: np.ndarray, robot_radius: float, config: PassageGuardConfig) -> PassageVerdict:
    """Whether to hold the robot before the band stretch of ``path`` ahead (world frame; see the
    module doc). ``centres``, ``velocities``, ``radii``: the moving tracks now."""
    ahead = path_ahead(np.asarray(path, dtype=float), np.asarray(robot_xy, dtype=float), config.look_ahead)
    pts, s = _resample(ahead, 0.05)
    in_band = memory.band_gap(pts) < config.band_clearance
    if not in_band.any():
        return PassageVerdict(False, "no band on the path ahead")
    if in_band[0]:
        return PassageVerdict(False, "already in the band (the give-way's)")
    i0 = int(np.argmax(in_band))
    # The stretch ends where the path leaves the band for good: a path along the band's edge
    # dips in and out of it, and each dip is part of one walk through.
    band_idx = np.flatnonzero(in_band)
    breaks = np.flatnonzero(np.diff(s[band_idx]) > config.rejoin)
    i1 = int(band_idx[breaks[0]]) if len(breaks) else int(band_idx[-1])
    start, end = float(s[i0]), float(s[i1])
    if start > config.approach:
        return PassageVerdict(False, f"band {start:.2f} m ahead", start, end)
    centres = np.asarray(centres, dtype=float).reshape(-1, 2)
    velocities = np.asarray(velocities, dtype=float).reshape(-1, 2)
    radii = np.asarray(radii, dtype=float).reshape(-1)
    # The movers in view, and the one(s) last seen walking if that was a while ago but recently
    # (out of view, e.g. behind a wall): predicted from earlier walks from where they were.
    since = np.zeros(len(centres))  # s since each mover checked was seen
    last = memory.last_seen()
    if len(last) and OUT_OF_VIEW_AFTER < now - last[0, 0] <= config.out_of_view:
        centres = np.vstack([centres, last[:, 1:3]])
        velocities = np.vstack([velocities, last[:, 3:5]])
        radii = np.r_[radii, np.full(len(last), GHOST_RADIUS)]
        since = np.r_[since, np.full(len(last), float(now - last[0, 0]))]
    if len(centres) == 0:
        return PassageVerdict(False, "no mover", start, end)
    # The robot's drive through: standing start_delay s, then at speed to exit_margin past the end.
    dt = 0.2
    reach = min(end + config.exit_margin, float(s[-1]))
    t_end = config.start_delay + reach / config.speed
    times = np.arange(0.0, t_end + 1e-9, dt)
    along = np.clip((times - config.start_delay) * config.speed, 0.0, reach)
    robot = np.c_[np.interp(along, s, pts[:, 0]), np.interp(along, s, pts[:, 1])]
    for c, v, r, ago in zip(centres, velocities, radii, since):
        if np.hypot(*(robot - c).T).min() > MAX_MOVER_SPEED * (t_end + ago) + robot_radius + r + config.margin:
            continue  # too far to meet the robot in the band stretch whatever it does
        preds = memory.predict(now - ago, c, v, times + ago, match_distance=config.match_distance,
                               match_heading=config.match_heading, learned_only=bool(ago > 0))
        if ago > 0 and (not preds or any(np.isnan(p).any() for p in preds)):
            # Out of view and no earlier walk from there recorded over the drive through: where
            # it is is unknown; it walked here less than out_of_view s ago: wait to see it.
            return PassageVerdict(True, f"mover last seen {ago:.1f} s ago at ({c[0]:.2f}, {c[1]:.2f}) is out of view and "
                                        f"its walk from there is not known for the {times[-1]:.1f} s through the band stretch "
                                        f"{start:.2f}-{end:.2f} m ahead", start, end)
        for pred in preds:
            gap = np.hypot(*(pred - robot).T) - robot_radius - r - (config.margin + config.margin_rate * times)
            if (gap < 0).any():
                k = int(np.argmax(gap < 0))
                seen = f" (out of view, last seen {ago:.1f} s ago)" if ago > 0 else ""
                return PassageVerdict(True, f"mover at ({c[0]:.2f}, {c[1]:.2f}){seen} predicted at ({pred[k, 0]:.2f}, {pred[k, 1]:.2f}) "
                                            f"in {times[k]:.1f} s, where the robot would be in the band stretch "
                                            f"{start:.2f}-{end:.2f} m ahead", start, end)
    return PassageVerdict(False, f"band stretch {start:.2f}-{end:.2f} m ahead is clear", start, end)
