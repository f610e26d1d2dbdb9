"""Passage guard: do not enter the stretch of the path where people walk while one is coming.

A reactive give-way cannot clear a person walking a narrow passage at 0.6 m/s: there is no
side to pull aside to and a robot backing at 0.4 m/s is caught. The robot has to wait *outside*
the people's way and go through when it can be out again before a person arrives. Two parts:

* :class:`MoverMemory`: where moving obstacles have walked (their tracked centres over the last
  ``memory`` s, a decaying record of the scan tracker's movers: never ground truth) -- the
  *band* -- and how each walked on from where it was: a mover seen again where (and heading the
  way) one walked before is predicted to walk on as that one did (a person who turned at the end
  of a corridor turns there again: the learned-motion-pattern prediction of Bennewitz et al.),
  besides at constant velocity. Both predictions count. Where nothing is learned yet (the first
  walk), a straight line into a wall of the static map turns along it, either way
  (``WallFilter.turns``): a person turning a corner towards the robot is tracked walking on
  into the wall for a second.
* :func:`check_passage`: the *stretch* of the robot's path ahead that lies in the band (within
  ``band_clearance`` of a remembered mover centre: the robot's and a person's radii plus a
  margin). The robot is held before the stretch when it cannot drive through it (at the speed
  it was *measured* to drive lately, :class:`DriveSpeed`, at most ``speed``, after the start
  delay it was measured to take, at least ``start_delay``, plus ``exit_margin``) without coming
  within ``margin`` (growing by ``margin_rate`` per second of prediction) of a mover's predicted
  position. A loaded machine drives the robot at half its nominal speed: a drive through
  predicted at the nominal speed ends before the real one does, and the person is back first.

A person out of view (behind a wall) is predicted from their *last real sighting*: the last
sample of the last walk the memory saw long and far enough to be a person
(:meth:`MoverMemory.last_sighting`), not the last moving track anywhere: clutter that a moving
robot's scan makes look moving for a few scans must not take the person's place.

The Behaviors component (``BehaviorsConfig.passage_guard``) runs the check on every step and
holds the robot on its command input (above the Controller's) while it says so.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import attrs
import numpy as np

from emos.config import validators as V

from ..costmap.people import BAND_RESOLUTION

if TYPE_CHECKING:
    from ..controllers.movers import WallFilter

__all__ = ["DriveSpeed", "MoverMemory", "PassageGuardConfig", "PassageVerdict", "check_passage", "walks_past"]


@attrs.define(frozen=True)
class PassageGuardConfig:
    """When the robot waits before the people's way (see the module doc).

    ``band_clearance`` (m): a path point this near a remembered mover centre is in the band
    (robot radius + person radius + a margin). ``approach`` (m): the robot is held when the
    stretch begins within this distance ahead along the path. ``look_ahead`` (m of path
    checked). ``rejoin`` (m): band stretches of the path less than this apart are one stretch.
    ``speed`` (m/s: the most the robot is assumed to drive the stretch at; the speed it was
    measured to drive at lately when lower, never below ``min_speed``), ``start_delay`` (s
    before it moves: the least; the measured delay when longer), ``exit_margin`` (m past the
    stretch it must reach). ``margin`` (m kept
    from a predicted mover; ``margin_rate`` m more per s of prediction). ``max_hold`` (s): a wait
    for an unseen person (``unseen_wait``) longer than this gives up and lets the robot go; a
    hold for a mover (in view or out of it: the scan tracker drops a track that stands for a
    second, so a mover is a person coming by or back) goes on until the way is clear, and says
    so once past it, or until a mover whose walk from there is not known has just walked out of
    view away from the stretch where the movers before stayed away longer than the drive through
    takes (``PassageVerdict.just_left``: a person pacing out of view and back leaves no window
    otherwise, and that is when they are farthest from coming back). ``release_time`` (s): a hold ends once the way has been clear this long (a
    person turning at the end of their walk is tracked slow and heading away for a moment: one
    clear verdict then is not a window). ``out_of_view`` (s): with no mover in view, the one last
    seen this recently is predicted as earlier walks from where it was went on (it walked out of the scan's view,
    e.g. behind a wall, and comes back). ``unseen_wait`` (s, 0: off): with nobody in view or seen
    within ``out_of_view`` (the people who walked the band are somewhere out of view), the robot
    waits at the band's edge up to this long for one to come into view before it goes in
    (the Behaviors: ``PassageVerdict.unseen``). ``returns``: a mover out of view past the earlier
    walks' records is predicted as movers that left the view there came back
    (:meth:`MoverMemory.predict_return`) instead of holding the robot until it is seen again.
    ``memory`` (s a mover's walk is remembered), ``band_memory`` (s, at least ``memory``: how
    long the give-way's yield moves keep out of where movers walked; a walk the guard no longer
    predicts from is still a way a person may come again, and a robot held for minutes where it
    cannot see one of the person's walks pulled aside onto it), ``match_distance`` (m) and
    ``match_heading`` (rad): how near and how alike in heading an earlier walk must be to
    predict from it. ``known_walks``: the give-way (``GiveWayConfig``) does not start for a mover
    whose straight line meets the robot while it walks where earlier walks went the same way
    and every one of them keeps clear of it (:func:`walks_past`: a person coming along the band
    towards a robot waiting outside it turns at the corner of their walk, as they did before;
    one who leaves the remembered walks, or comes within the give-way's ``near_distance``, is
    given way to as before)."""

    enabled: bool = attrs.field(default=False, validator=attrs.validators.instance_of(bool))
    band_clearance: float = attrs.field(default=0.55, validator=V.number(gt=0, le=5, finite=True, what="metres"))
    approach: float = attrs.field(default=0.6, validator=V.number(ge=0, le=5, finite=True, what="metres"))
    rejoin: float = attrs.field(default=1.0, validator=V.number(ge=0, le=10, finite=True, what="metres"))
    look_ahead: float = attrs.field(default=6.0, validator=V.number(gt=0, le=50, finite=True, what="metres"))
    speed: float = attrs.field(default=0.4, validator=V.number(gt=0, le=5, finite=True, what="m/s"))
    min_speed: float = attrs.field(default=0.1, validator=V.number(gt=0, le=5, finite=True, what="m/s"))
    start_delay: float = attrs.field(default=1.0, validator=V.number(ge=0, le=10, finite=True, what="seconds"))
    exit_margin: float = attrs.field(default=0.3, validator=V.number(ge=0, le=5, finite=True, what="metres"))
    margin: float = attrs.field(default=0.15, validator=V.number(ge=0, le=3, finite=True, what="metres"))
    margin_rate: float = attrs.field(default=0.02, validator=V.number(ge=0, le=1, finite=True, what="m/s"))
    max_hold: float = attrs.field(default=60.0, validator=V.number(gt=0, le=3600, finite=True, what="seconds"))
    release_time: float = attrs.field(default=1.0, validator=V.number(ge=0, le=60, finite=True, what="seconds"))
    out_of_view: float = attrs.field(default=15.0, validator=V.number(ge=0, le=600, finite=True, what="seconds"))
    unseen_wait: float = attrs.field(default=0.0, validator=V.number(ge=0, le=600, finite=True, what="seconds"))
    returns: bool = attrs.field(default=False, validator=attrs.validators.instance_of(bool))
    memory: float = attrs.field(default=180.0, validator=V.number(gt=0, le=86400, finite=True, what="seconds"))
    band_memory: float = attrs.field(default=900.0, validator=V.number(gt=0, le=86400, finite=True, what="seconds"))
    match_distance: float = attrs.field(default=0.35, validator=V.number(gt=0, le=5, finite=True, what="metres"))
    match_heading: float = attrs.field(default=math.radians(40.0), validator=V.number(gt=0, le=math.pi, finite=True, what="radians"))
    known_walks: bool = attrs.field(default=True, validator=attrs.validators.instance_of(bool))


@attrs.define(frozen=True)
class PassageVerdict:
    """``hold``: wait before the stretch now; ``reason`` says why (or why not); ``start``,
    ``end``: the stretch's arc lengths along the path ahead (m; None when no stretch ahead);
    ``unseen``: the stretch is ahead and no mover is known (in view or seen lately): where the
    people who walked the band are is unknown (``PassageGuardConfig.unseen_wait``).
    ``just_left``: held for a mover that walked out of view less than ``JUST_LEFT`` s ago, away
    from the stretch, with no earlier walk from there remembered, where every mover that left
    the view there before stayed out of it longer than the drive through takes
    (:meth:`MoverMemory.absences`): where it is is unknown, but it is as far from coming back as
    it will be (a hold past ``max_hold`` lets the robot go then, ``Behaviors._step_hold``)."""

    hold: bool
    reason: str
    start: float | None = None
    end: float | None = None
    unseen: bool = False
    just_left: bool = False


SAMPLE_PERIOD = 0.1  # s between the remembered samples of one mover
MIN_SPEED = 0.3  # m/s: slower tracks are not remembered as walking (people walk 0.5 to 1.5 m/s; clutter a
# moving robot's scan makes look moving is mostly slower)
CLOCK_BACK = 1.0  # s: a sample this much older than the last one means the clock went back
GAP_LIMIT = 0.6  # s: a longer gap in the record ends a remembered walk (the mover was not seen)
MATCH_AGE = 2.0  # s: a walk is predicted from one at least this old (not the walk going on)
LEADS = (0.0, -0.5, 0.5)  # s: the earlier walk is followed this much ahead (timing uncertainty of a track)
MAX_PASSES = 4  # earlier passes tried, most recent first (the guard runs at the component's rate)
MAX_MOVER_SPEED = 1.5  # m/s: a mover farther from the robot's drive than this covers is not checked
# Two samples are one mover's walk when it could have walked from one to the other at MAX_MOVER_SPEED (plus
# LINK_SLACK m of the tracked centre's jitter); faster links took a phantom's walk on as a person's 1.3 m away.
LINK_SLACK = 0.1  # m
GHOST_RADIUS = 0.25  # m: the radius of a mover out of view (a person)
JUST_LEFT = 1.5  # s: a mover out of view no longer than this (past OUT_OF_VIEW_AFTER) has just left it
OUT_OF_VIEW_AFTER = 0.5  # s: a mover not recorded walking for longer is out of view (or stopped)
# A walk is a person's (a real sighting) once recorded unbroken for this long and this far from
# where it began: clutter that a moving robot's scan makes look moving lasts a few scans and
# stays where it was (its centre jitters), a walking person covers 0.5 m and more per second.
REAL_WALK_TIME = 1.0  # s
REAL_WALK_DISTANCE = 0.5  # m
MAX_WALKS = 32  # real walks kept for last_sighting (the latest matter)
# A real walk that begins this soon after the previous one ended is the mover coming back into
# view (a person who walked down a corridor out of the scan's view and back):
# MoverMemory.predict_return learns how long it stayed out of view and where it came back.
RETURN_WITHIN = 30.0  # s
RETURN_WALK_TIME = 2.0  # s: walks shorter than this neither leave nor come back in MoverMemory.returns


@attrs.define
class _Walk:
    """One mover's unbroken record in :class:`MoverMemory`: where and when it began, its first
    and last samples (t, x, y, vx, vy), and whether it is a real walk yet."""

    t0: float
    xy0: tuple[float, float]
    last: tuple[float, float, float, float, float]
    real: bool = False
    first: tuple[float, float, float, float, float] | None = None


class DriveSpeed:
    """How fast the robot actually drove lately (odometry poses on the component's clock): the
    speed the passage guard predicts a drive through at, instead of a nominal one. A loaded
    machine runs the controller late and the robot drives at a fraction of its set speed.

    ``speed()``: the median (``QUANTILE``) of the speeds over ``span`` s pieces of the last
    ``window`` s of driving (``observe(..., driving=True)``: the Controller's, not a behavior's)
    in which the robot moved (faster than ``MOVING``: not standing for a picture or turning in
    place); None before ``MIN_PIECES`` such pieces. ``start_delay()``: the longest of the last delays from a hold's end to the robot
    having moved ``START_DISTANCE`` (``released()`` marks a hold's end)."""

    MOVING = 0.05  # m/s: slower pieces are standing (a picture) or turning in place, not driving
    QUANTILE = 0.5
    MIN_PIECES = 5
    START_DISTANCE = 0.1  # m
    MAX_DELAYS = 5
    MAX_DELAY = 10.0  # s: a longer one was not a start (the robot stayed for another reason)

    def __init__(self, window: float = 30.0, span: float = 1.0) -> None:
        self.window, self.span = float(window), float(span)
        self._poses: list[tuple[float, float, float]] = []
        self._pieces: list[tuple[float, float]] = []  # (end time, m/s) of each span while moving
        self._release: tuple[float, float, float] | None = None
        self._delays: list[float] = []

    def observe(self, t: float, x: float, y: float, driving: bool = True) -> None:
        """The robot at (x, y) at ``t`` s; ``driving``: on its way (not held, not giving way: a
        behavior's moves are not how fast it drives through)."""
        t = float(t)
        if self._poses and t < self._poses[-1][0]:  # the clock went back: start again
            self._poses, self._pieces, self._release = [], [], None
        if not driving:
            # Held again (or a behavior's move) before the robot had driven off: that release
            # was no start, and timing it to the next drive would count the hold in the delay.
            self._poses, self._release = [], None
        self._poses.append((t, float(x), float(y)))
        while len(self._poses) > 1 and t - self._poses[1][0] >= self.span:
            self._poses.pop(0)
        t0, x0, y0 = self._poses[0]
        if t - t0 >= self.span:
            v = math.hypot(x - x0, y - y0) / (t - t0)
            if v >= self.MOVING:
                self._pieces.append((t, v))
            self._poses = [self._poses[-1]]
        while self._pieces and self._pieces[0][0] < t - self.window:
            self._pieces.pop(0)
        if self._release is not None:
            rt, rx, ry = self._release
            if t - rt > self.MAX_DELAY:
                self._release = None
            elif math.hypot(x - rx, y - ry) >= self.START_DISTANCE:
                self._delays = [*self._delays[-(self.MAX_DELAYS - 1):], t - rt]
                self._release = None

    def released(self, t: float, x: float, y: float) -> None:
        """A hold ended at ``t`` with the robot at (x, y): time its start."""
        self._release = (float(t), float(x), float(y))

    def speed(self) -> float | None:
        if len(self._pieces) < self.MIN_PIECES:
            return None
        return float(np.quantile([v for _, v in self._pieces], self.QUANTILE))

    def start_delay(self) -> float | None:
        return max(self._delays) if self._delays else None

    def since_release(self, t: float) -> float | None:
        """S since a hold's end (``released``) while the robot has not driven off yet; None when
        no release is being timed (it drove off, was held again, or ``MAX_DELAY`` passed)."""
        return None if self._release is None else max(0.0, float(t) - self._release[0])


class MoverMemory:
    """Where movers walked (world frame) for ``memory`` s: samples (t, x, y, vx, vy) of the
    moving tracks, at most one per ``SAMPLE_PERIOD`` per mover; and the cells of the band they
    walked for ``band_memory`` s (at least ``memory``; :meth:`lasting_band_cells`)."""

    def __init__(self, memory: float = 180.0, band_memory: float | None = None) -> None:
        self.memory = float(memory)
        self.band_memory = max(self.memory, float(band_memory)) if band_memory is not None else self.memory
        self._band_seen: dict[tuple[int, int], float] = {}  # band cell (index at BAND_RESOLUTION) -> time last walked
        self._lasting: np.ndarray | None = None  # _band_seen as rows (cell x, cell y, t), until the next sample
        self._rows: list[tuple[float, float, float, float, float]] = []
        self._array: np.ndarray | None = None
        self._cells: np.ndarray | None = None  # band_cells, until the next sample
        self._returns: list[tuple[tuple[float, ...], tuple[float, ...]]] | None = None  # returns(), until the next sample
        self._last_t = -math.inf
        self._walks: list[_Walk] = []  # each mover's unbroken record (last_sighting)

    def observe(self, t: float, centres: np.ndarray, velocities: np.ndarray) -> None:
        """Record the moving tracks seen at ``t`` s: ``centres`` and ``velocities`` (M, 2)."""
        t = float(t)
        if t < self._last_t - CLOCK_BACK and self._rows:
            # The clock went back (a restarted simulator starts its clock again): the band stays,
            # the record is moved to end just before now, its walks' timing kept.
            shift = t - SAMPLE_PERIOD - self._last_t
            self._rows = [(r[0] + shift, *r[1:]) for r in self._rows]
            self._last_t += shift
            self._array = self._returns = self._lasting = None
            self._band_seen = {k: v + shift for k, v in self._band_seen.items()}
            for w in self._walks:
                w.t0 += shift
                w.last = (w.last[0] + shift, *w.last[1:])
                if w.first is not None:  # returns() times the reappearance from it
                    w.first = (w.first[0] + shift, *w.first[1:])
        if t < self._last_t + SAMPLE_PERIOD:
            return
        centres = np.asarray(centres, dtype=float).reshape(-1, 2)
        velocities = np.asarray(velocities, dtype=float).reshape(-1, 2)
        fast = np.hypot(velocities[:, 0], velocities[:, 1]) >= MIN_SPEED
        if not fast.any():
            return
        self._last_t = t
        self._rows.extend((t, float(c[0]), float(c[1]), float(v[0]), float(v[1])) for c, v in zip(centres[fast], velocities[fast]))
        self._follow_walks(self._rows[-int(fast.sum()):])
        cut = t - self.memory
        if self._rows[0][0] < cut:
            self._rows = [r for r in self._rows if r[0] >= cut]
        for c in np.round(centres[fast] / BAND_RESOLUTION).astype(np.int64):
            self._band_seen[(int(c[0]), int(c[1]))] = t
        self._array = self._cells = self._returns = self._lasting = None

    def _follow_walks(self, rows: list[tuple[float, float, float, float, float]]) -> None:
        """Extend each open walk by the nearest new sample it could have walked to
        (``MAX_MOVER_SPEED``, as ``_walk_from`` links samples), start a walk for each sample left; a walk is
        real once long and far enough (``REAL_WALK_TIME``, ``REAL_WALK_DISTANCE``)."""
        t = rows[0][0]
        open_walks = [w for w in self._walks if t - w.last[0] <= GAP_LIMIT]
        taken: set[int] = set()
        for row in sorted(rows, key=lambda r: min((math.hypot(r[1] - w.last[1], r[2] - w.last[2]) for w in open_walks),
                                                  default=math.inf)):
            best, best_d = None, math.inf
            for i, w in enumerate(open_walks):
                d = math.hypot(row[1] - w.last[1], row[2] - w.last[2])
                if i not in taken and d <= MAX_MOVER_SPEED * (t - w.last[0]) + LINK_SLACK and d < best_d:
                    best, best_d = i, d
            if best is None:
                self._walks.append(_Walk(t, (row[1], row[2]), row, first=row))
                continue
            taken.add(best)
            w = open_walks[best]
            w.last = row
            if not w.real and t - w.t0 >= REAL_WALK_TIME and math.hypot(row[1] - w.xy0[0], row[2] - w.xy0[1]) >= REAL_WALK_DISTANCE:
                w.real = True
        # Keep the open walks and the latest real ones (a walk that never became real is forgotten when it ends).
        live = [w for w in self._walks if t - w.last[0] <= GAP_LIMIT]
        done = [w for w in self._walks if t - w.last[0] > GAP_LIMIT and w.real and w.last[0] >= t - self.memory]
        self._walks = done[-MAX_WALKS:] + live

    def last_sighting(self, now: float) -> tuple[np.ndarray, np.ndarray]:
        """The last real sighting of the movers: (K, 5) rows (t, x, y, vx, vy), the last sample of
        each real walk that ended (or goes on) at the latest time a real walk was recorded, and
        (K,) their ages at ``now`` s. Short tracks (clutter the scan makes look moving) never
        take the place of a person who walked out of view."""
        real = [w for w in self._walks if w.real]
        if not real:
            return np.zeros((0, 5)), np.zeros(0)
        latest = max(w.last[0] for w in real)
        rows = np.array([w.last for w in real if w.last[0] >= latest - SAMPLE_PERIOD], dtype=float).reshape(-1, 5)
        return rows, float(now) - rows[:, 0]

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
            self._cells = (np.unique(np.round(rows[:, 1:3] / BAND_RESOLUTION).astype(np.int64), axis=0) * BAND_RESOLUTION if len(rows)
                           else np.zeros((0, 2)))
        return self._cells

    def lasting_band_cells(self, now: float) -> np.ndarray:
        """(K, 2) centres of the 5 cm cells where movers walked in the last ``band_memory`` s
        before ``now``: where a yield move should not end (a way people walked is walked again,
        even once the guard no longer predicts from it)."""
        if self._lasting is None:  # (cell x, cell y, time last walked), until the next sample
            self._lasting = np.array([(*k, t) for k, t in self._band_seen.items()], dtype=float).reshape(-1, 3)
        keep = self._lasting[:, 2] >= float(now) - self.band_memory
        if not keep.all():
            self._band_seen = {k: t for k, t in self._band_seen.items() if t >= float(now) - self.band_memory}
            self._lasting = self._lasting[keep]
        out: np.ndarray = self._lasting[:, :2] * BAND_RESOLUTION
        return out

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
            jumps = np.flatnonzero(np.hypot(*np.diff(seg[:, 1:3], axis=0).T) > MAX_MOVER_SPEED * np.diff(seg[:, 0]) + LINK_SLACK)
            seg = seg[:int(jumps[0]) + 1] if len(jumps) else seg  # another mover: the walk's record ends
            return list(seg[:, 0] - t0), list(seg[:, 1:3]), seg[-1]
        walk_t, walk_xy = [0.0], [rows[k, 1:3]]
        j, last = k + 1, rows[k]
        while j < len(rows) and rows[j, 0] - t0 <= horizon + SAMPLE_PERIOD:
            if rows[j, 0] - last[0] > GAP_LIMIT:
                break
            group = rows[j:int(np.searchsorted(rows[:, 0], rows[j, 0], side="right"))]
            i = int(np.argmin(np.hypot(group[:, 1] - last[1], group[:, 2] - last[2])))
            if math.hypot(group[i, 1] - last[1], group[i, 2] - last[2]) <= MAX_MOVER_SPEED * (rows[j, 0] - last[0]) + LINK_SLACK:
                last = group[i]
                walk_t.append(float(last[0] - t0))
                walk_xy.append(last[1:3])
            j += len(group)
        return walk_t, walk_xy, last

    def predict(self, now: float, centre: np.ndarray, velocity: np.ndarray, times: np.ndarray, *,
                match_distance: float = 0.35, match_heading: float = math.radians(40.0),
                learned_only: bool = False) -> list[np.ndarray]:
        """Predicted centres (len(times), 2) of a mover at ``centre`` with ``velocity`` now, at
        ``times`` s from now: at constant velocity, and, when an earlier walk passed here the
        same way, as that walk went on (until the record of it ends; then as a mover that left
        the record there came back, :meth:`returns`, when one did; else at its last velocity).
        A track slower than a walk (``MIN_SPEED``: a person turning round at the end of their
        walk, where the tracker's velocity passes through zero, or setting off) has no "same
        way": every way an earlier walk went on from here is a prediction.
        ``learned_only``: only the earlier walk, and NaN past its record (a mover out of view:
        where it went is unknown but for what movers did before)."""
        c = np.asarray(centre, dtype=float)
        v = np.asarray(velocity, dtype=float)
        times = np.asarray(times, dtype=float)
        out = [] if learned_only else [c[None, :] + v[None, :] * times[:, None]]
        rows = self.samples()
        speed = float(np.hypot(*v))
        slow = speed < MIN_SPEED
        if len(rows) == 0 or (slow and learned_only):
            return out
        old = rows[:, 0] <= now - MATCH_AGE
        near = np.hypot(rows[:, 1] - c[0], rows[:, 2] - c[1]) <= match_distance
        if slow:
            match = np.flatnonzero(old & near)
        else:
            rs = np.hypot(rows[:, 3], rows[:, 4])
            cos = (rows[:, 3] * v[0] + rows[:, 4] * v[1]) / np.maximum(rs * speed, 1e-9)
            match = np.flatnonzero(old & near & (cos >= math.cos(match_heading)))
        if len(match) == 0:
            return out
        horizon = (float(times[-1]) if len(times) else 0.0) + max(LEADS)
        # One pass by here: matches less than a second apart (for a slow track also split where
        # the walk turned: the way out and the way back are two passes); of each, the sample
        # nearest the mover.
        cuts = np.diff(rows[match, 0]) > 1.0
        if slow:
            cuts |= np.einsum("ij,ij->i", rows[match[:-1], 3:5], rows[match[1:], 3:5]) < 0.0
        passes = np.split(match, np.flatnonzero(cuts) + 1)
        walks: list[tuple[list[float], list[np.ndarray], np.ndarray]] = []
        for group in passes[::-1][:2 * MAX_PASSES if slow else MAX_PASSES]:
            k = int(group[np.argmin(np.hypot(rows[group, 1] - c[0], rows[group, 2] - c[1]))])
            walk = self._walk_from(k, horizon) if learned_only else self._walk_on(k, horizon)
            if slow:  # every way on from here counts
                walks.append(walk)
                continue
            # The most recent earlier walk through here whose record covers the horizon (the
            # mover was not always in view), else the one recorded longest.
            if not walks or walk[0][-1] > walks[0][0][-1]:
                walks = [walk]
            if walks[0][0][-1] >= horizon:
                break
        for walk_t, walk_xy, last in walks:
            if len(walk_t) < 2:
                continue
            wt, wxy = np.array(walk_t), np.array(walk_xy)
            shift = c - wxy[0]  # the walk as it went, from where the mover is now
            # The track's velocity lags its walk (a fit over the last second): near a turn it
            # still says "down" when the person walks up again. The walk is also taken a little
            # earlier and later (LEADS s), each a hypothesis.
            for lead in LEADS:
                at = np.maximum(times + lead, 0.0)
                pred = np.c_[np.interp(at, wt, wxy[:, 0]), np.interp(at, wt, wxy[:, 1])] + shift
                beyond = at > wt[-1]
                if beyond.any():  # past the record: on at the walk's last velocity (unknown for a mover out of view)
                    pred[beyond] = np.nan if learned_only else wxy[-1] + shift + last[3:5] * (at[beyond] - wt[-1])[:, None]
                out.append(pred)
        return out

    def _walk_on(self, k: int, horizon: float, chains: int = 2) -> tuple[list[float], list[np.ndarray], np.ndarray]:
        """:meth:`_walk_from`, and where its record ends before ``horizon`` at the end of a
        remembered walk that a mover came back from (:meth:`returns`: it left the tracker's
        view, or slowed below a walk at a turn), on out along its heading and back to where it
        reappeared when it did, then as that walk went (at most ``chains`` times): a person
        heading for the end of their walk turns there, as before, rather than walking on
        through the wall at the last velocity."""
        walk_t, walk_xy, last = self._walk_from(k, horizon)
        for _ in range(chains):
            if walk_t[-1] >= horizon:
                break
            back_row = self._reappearance(last)
            if back_row is None:
                break
            key_t, key_xy = _out_and_back(np.asarray(last[1:3]), np.asarray(last[3:5]), np.asarray(back_row[1:3]),
                                          back_row[0] - float(last[0]))
            t_back = walk_t[-1] + float(key_t[-1])
            more_t, more_xy, last = self._walk_from(self._row_index(back_row), max(horizon - t_back, 0.0))
            walk_t = walk_t + [walk_t[-1] + float(t) for t in key_t[1:-1]] + [t_back + t for t in more_t]
            walk_xy = walk_xy + list(key_xy[1:-1]) + list(more_xy)
        return walk_t, walk_xy, last

    def _reappearance(self, exit_row: np.ndarray) -> tuple[float, ...] | None:
        """The first sample of the walk that came back after the remembered walk ending at
        ``exit_row`` (:meth:`returns`), if it is remembered still; else None."""
        rows = self.samples()
        for exit_, back in self.returns():
            if abs(exit_[0] - float(exit_row[0])) <= SAMPLE_PERIOD / 2 and \
                    math.hypot(exit_[1] - float(exit_row[1]), exit_[2] - float(exit_row[2])) <= 0.1:
                return back if len(rows) and back[0] >= rows[0, 0] - 1e-9 else None
        return None

    def returns(self) -> list[tuple[tuple[float, ...], tuple[float, ...]]]:
        """(exit, reappearance) samples (t, x, y, vx, vy), oldest first: where and when movers
        came back into view. Of the walks recorded for ``RETURN_WALK_TIME`` s at least (a
        person going somewhere; the phantom walk a person's shadow makes, its edge sweeping
        along the wall behind them, lasts about a second), each that began within
        ``RETURN_WITHIN`` s after another ended (not while that was still in view) is the return
        of the one of those that ended nearest to where it began, and each ended walk returns
        once, the first time."""
        if self._returns is not None:  # asked for every pass of every mover on each guard step
            return list(self._returns)
        real = sorted((w for w in self._walks if w.real and w.first is not None and w.last[0] - w.t0 >= RETURN_WALK_TIME),
                      key=lambda w: w.t0)
        pairs: dict[int, tuple[_Walk, _Walk]] = {}  # id(exit walk) -> (exit, return)
        for b in real:
            assert b.first is not None
            gone = [a for a in real if GAP_LIMIT < b.t0 - a.last[0] <= RETURN_WITHIN and id(a) not in pairs]
            if gone:
                a = min(gone, key=lambda w: math.hypot(w.last[1] - b.first[1], w.last[2] - b.first[2]))  # type: ignore[index]
                pairs[id(a)] = (a, b)
        out = [(a.last, b.first) for a, b in pairs.values() if b.first is not None]
        self._returns = sorted(out, key=lambda pair: pair[0][0])
        return list(self._returns)

    def _returns_like(self, centre: np.ndarray, velocity: np.ndarray, match_distance: float,
                      match_heading: float) -> list[tuple[tuple[float, ...], tuple[float, ...]]]:
        """The (exit, reappearance) pairs of :meth:`returns`, most recent first, whose exit was
        within ``match_distance`` of ``centre`` heading within ``match_heading`` of ``velocity``."""
        c, v = np.asarray(centre, dtype=float), np.asarray(velocity, dtype=float)
        speed = float(np.hypot(*v))
        out = []
        for exit_row, back_row in self.returns()[::-1]:
            ev = np.asarray(exit_row[3:5])
            if math.hypot(exit_row[1] - c[0], exit_row[2] - c[1]) <= match_distance and \
                    float(ev @ v) >= math.cos(match_heading) * float(np.hypot(*ev)) * speed:
                out.append((exit_row, back_row))
        return out

    def absences(self, centre: np.ndarray, velocity: np.ndarray, *, match_distance: float = 0.35,
                 match_heading: float = math.radians(40.0)) -> list[float]:
        """Seconds out of view of the movers that left the view near ``centre`` heading like
        ``velocity`` and came back (:meth:`returns`), most recent first."""
        return [float(back[0] - exit_[0]) for exit_, back in self._returns_like(centre, velocity, match_distance, match_heading)]

    def predict_return(self, now: float, centre: np.ndarray, velocity: np.ndarray, times: np.ndarray, *,
                       match_distance: float = 0.35, match_heading: float = math.radians(40.0)) -> list[np.ndarray]:
        """Predicted centres (len(times), 2) of a mover that walked out of view at ``centre`` with
        ``velocity`` at ``now``, at ``times`` s from then, as movers that left the view there the
        same way came back before (:meth:`returns`): on at its speed, turning back so as to be where
        the earlier one reappeared when it did (a person walking down a corridor and back), then
        on as that earlier walk went from there; [] when no such return is remembered. Each of the
        latest ``MAX_PASSES`` returns is a prediction, each taken ``LEADS`` s early and late."""
        c = np.asarray(centre, dtype=float)
        v = np.asarray(velocity, dtype=float)
        times = np.asarray(times, dtype=float)
        speed = float(np.hypot(*v))
        if speed < MIN_SPEED:
            return []
        out: list[np.ndarray] = []
        for exit_row, back_row in self._returns_like(c, v, match_distance, match_heading):
            if exit_row[0] > now - MATCH_AGE:
                continue
            rows = self.samples()
            if not len(rows) or back_row[0] < rows[0, 0] - 1e-9:
                continue  # the walk back is forgotten already
            away = back_row[0] - exit_row[0]  # s out of view
            shift = c - np.asarray(exit_row[1:3])
            turn_t, turn_xy = _out_and_back(c, v, np.asarray(back_row[1:3]) + shift, away)
            walk_t, walk_xy, last = self._walk_from(self._row_index(back_row), float(times[-1]) + max(LEADS) if len(times) else 0.0)
            key_t = np.r_[turn_t[:-1], away + np.asarray(walk_t, dtype=float)]
            key_xy = np.vstack([turn_xy[:-1], np.asarray(walk_xy, dtype=float) + shift])
            for lead in LEADS:
                at = np.maximum(times + lead, 0.0)
                pred = np.c_[np.interp(at, key_t, key_xy[:, 0]), np.interp(at, key_t, key_xy[:, 1])]
                beyond = at > key_t[-1]  # past the record of the walk back: on at its last velocity
                pred[beyond] = key_xy[-1] + np.asarray(last[3:5]) * (at[beyond] - key_t[-1])[:, None]
                out.append(pred)
            if len(out) >= MAX_PASSES * len(LEADS):
                break
        return out

    def _row_index(self, row: tuple[float, ...]) -> int:
        """The index in :meth:`samples` of a remembered sample ``row`` (nearest at its time)."""
        rows = self.samples()
        lo = int(np.searchsorted(rows[:, 0], row[0] - 1e-9))
        hi = max(int(np.searchsorted(rows[:, 0], row[0] + 1e-9, side="right")), lo + 1)
        group = rows[lo:hi]
        return lo + int(np.argmin(np.hypot(group[:, 1] - row[1], group[:, 2] - row[2])))


def walks_past(memory: MoverMemory, now: float, centre: np.ndarray, velocity: np.ndarray, robot_xy: np.ndarray,
               robot_velocity: np.ndarray, reach: float, horizon: float, config: PassageGuardConfig) -> bool:
    """Whether the mover at ``centre`` with ``velocity`` walks where earlier walks went the same
    way (:meth:`MoverMemory.predict`'s walks from here, at each of their timings, ``LEADS``) and
    every such walk keeps its centre at least ``reach`` m from the robot's (at ``robot_xy``,
    moving at ``robot_velocity``, world frame) over ``horizon`` s. False when no earlier walk
    matches: a mover off the remembered walks is judged at constant velocity alone."""
    times = np.arange(0.0, horizon + 1e-9, 0.1)
    learned = memory.predict(now, np.asarray(centre, dtype=float), np.asarray(velocity, dtype=float), times,
                             match_distance=config.match_distance, match_heading=config.match_heading)[1:]
    if not learned:
        return False
    robot = np.asarray(robot_xy, dtype=float)[None, :2] + np.asarray(robot_velocity, dtype=float)[None, :2] * times[:, None]
    return all(float(np.hypot(*(walk - robot).T).min()) >= reach for walk in learned)


def _out_and_back(exit_xy: np.ndarray, velocity: np.ndarray, back_xy: np.ndarray, away: float) -> tuple[np.ndarray, np.ndarray]:
    """Key times (s from leaving, the last ``away``) and positions (3, 2) of a mover that left
    the record at ``exit_xy`` with ``velocity`` and came back into it at ``back_xy`` ``away`` s
    later: on along its heading at its speed, turning back so as to be at ``back_xy`` in time (a
    person walking down a corridor out of view and back, or to the end of their walk and back)."""
    speed = float(np.hypot(*velocity))
    if speed <= 1e-9:
        return np.array([0.0, away]), np.vstack([exit_xy, back_xy])
    turn_at = max(0.0, (speed * away - float(np.hypot(*(back_xy - exit_xy)))) / 2.0)
    turn_t = min(turn_at / speed, away)
    return np.array([0.0, turn_t, away]), np.vstack([exit_xy, exit_xy + velocity / speed * turn_at, back_xy])


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
                  velocities: np.ndarray, radii: np.ndarray, robot_radius: float, config: PassageGuardConfig, *,
                  measured_speed: float | None = None, measured_delay: float | None = None, under_way: bool = False,
                  let_go: float | None = None, walls: WallFilter | None = None) -> PassageVerdict:
    """Whether to hold the robot before the band stretch of ``path`` ahead (world frame; see the
    module doc). ``centres``, ``velocities``, ``radii``: the moving tracks now.
    ``measured_speed``, ``measured_delay``: how fast the robot drove lately and how long it took
    to start after a hold (:class:`DriveSpeed`; None: not measured yet): the drive through is
    predicted at ``min(speed, measured_speed)`` (at least ``min_speed``) after
    ``max(start_delay, measured_delay)``, less what of it is gone: none when the robot is
    ``under_way`` (driving already), the first ``let_go`` s when a hold let it go that long ago
    and it has not driven off yet (:meth:`DriveSpeed.since_release`: the drive the release judged
    began then; judging it as one a whole delay later re-held the robot on a window it had).
    A robot standing longer than the delay after its release is late: the whole delay again.
    ``walls`` (the static map's): a mover in view with no earlier walk from here the same way,
    whose straight line runs into a wall, is predicted turning along it either way
    (:meth:`WallFilter.turns`; the first lap, before anything is remembered)."""
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
    # The movers in view, and the one(s) last really seen walking if that was a while ago but
    # recently (out of view, e.g. behind a wall): predicted from earlier walks from where they were.
    since = np.zeros(len(centres))  # s since each mover checked was seen
    last, ages = memory.last_sighting(now)
    if len(last) and ages.min() > OUT_OF_VIEW_AFTER and ages.max() <= config.out_of_view:
        centres = np.vstack([centres, last[:, 1:3]])
        velocities = np.vstack([velocities, last[:, 3:5]])
        radii = np.r_[radii, np.full(len(last), GHOST_RADIUS)]
        since = np.r_[since, ages]
    if len(centres) == 0:
        return PassageVerdict(False, "no mover", start, end, unseen=True)
    # The robot's drive through: standing for the start delay, then at the speed it drives at
    # lately (never faster than the configured one) to exit_margin past the end.
    speed = max(min(config.speed, measured_speed if measured_speed is not None else config.speed), config.min_speed)
    delay = max(config.start_delay, measured_delay if measured_delay is not None else 0.0)
    if under_way:
        delay = 0.0
    elif let_go is not None and 0.0 <= let_go < delay:
        delay -= let_go
    dt = 0.2
    reach = min(end + config.exit_margin, float(s[-1]))
    t_end = delay + reach / speed
    times = np.arange(0.0, t_end + 1e-9, dt)
    along = np.clip((times - delay) * speed, 0.0, reach)
    robot = np.c_[np.interp(along, s, pts[:, 0]), np.interp(along, s, pts[:, 1])]
    for c, v, r, ago in zip(centres, velocities, radii, since):
        if np.hypot(*(robot - c).T).min() > MAX_MOVER_SPEED * (t_end + ago) + robot_radius + r + config.margin:
            continue  # too far to meet the robot in the band stretch whatever it does
        preds = memory.predict(now - ago, c, v, times + ago, match_distance=config.match_distance,
                               match_heading=config.match_heading, learned_only=bool(ago > 0))
        if walls is not None and ago == 0 and len(preds) == 1:  # nothing learned here: the walls say where it turns
            preds += walls.turns(c, v, r, times)
        back = ""
        if config.returns and ago > 0 and (not preds or any(np.isnan(p).any() for p in preds)):
            # Where it went out of view is past the earlier walks' records (they went out of view
            # there too): predicted as movers that left the view there came back, if remembered.
            returns = memory.predict_return(now - ago, c, v, times + ago, match_distance=config.match_distance,
                                            match_heading=config.match_heading)
            if returns:
                preds, back = returns, ", coming back as movers that left the view there did"
        if ago > 0 and (not preds or any(np.isnan(p).any() for p in preds)):
            # Out of view and no earlier walk from there recorded over the drive through: where
            # it is is unknown; it walked here less than out_of_view s ago: wait to see it.
            # Just gone, away from the stretch, where those who left before stayed away longer
            # than the drive through takes: the longest the way will be clear.
            middle = pts[(i0 + i1) // 2]
            away = memory.absences(c, v, match_distance=config.match_distance, match_heading=config.match_heading)
            just_left = bool(ago <= JUST_LEFT) and float(np.dot(v, c - middle)) > 0.0 and bool(away) and \
                min(away) - ago >= times[-1]
            gone = f" (movers that left the view there were out of it {min(away):.1f} s at the least)" if away else ""
            return PassageVerdict(True, f"mover last seen {ago:.1f} s ago at ({c[0]:.2f}, {c[1]:.2f}) is out of view and "
                                        f"its walk from there is not known for the {times[-1]:.1f} s through the band stretch "
                                        f"{start:.2f}-{end:.2f} m ahead{gone}", start, end, just_left=just_left)
        for pred in preds:
            gap = np.hypot(*(pred - robot).T) - robot_radius - r - (config.margin + config.margin_rate * times)
            if (gap < 0).any():
                k = int(np.argmax(gap < 0))
                seen = f" (out of view, last seen {ago:.1f} s ago{back})" if ago > 0 else ""
                return PassageVerdict(True, f"mover at ({c[0]:.2f}, {c[1]:.2f}){seen} predicted at ({pred[k, 0]:.2f}, {pred[k, 1]:.2f}) "
                                            f"in {times[k]:.1f} s, where the robot would be in the band stretch "
                                            f"{start:.2f}-{end:.2f} m ahead (driven at {speed:.2f} m/s after {delay:.1f} s)",
                                            start, end)
    return PassageVerdict(False, f"band stretch {start:.2f}-{end:.2f} m ahead is clear (driven at {speed:.2f} m/s after "
                                 f"{delay:.1f} s)", start, end)
