"""Swept-footprint check: does the robot's footprint touch an obstacle point while it executes
a command and then stops? Rotations included.

For every command the DriveManager is about to send, :class:`SweptFootprint` predicts the
robot's motion from the pose at which the obstacle points were seen (the scan's time) as

1. **latency**: the previous command, for the scan's age plus the actuation latency (compute,
   transport, the wheels' response);
2. **hold**: the new command, reached at the robot's acceleration limit and braked to at its
   braking limit, held for one command period;
3. **stop**: braking at the robot's braking limit on each axis, the yaw rate held for the
   body's yaw lag first (a skid-steer body keeps turning after its wheels stopped);

for a family of yaw gains (the body turns at ``gain`` times the commanded yaw rate: skid-steer
slip, and the forward speed lost while scrubbing), and checks the footprint at every sampled
pose against every point. The footprint is inflated by ``margin`` plus bounds of what sampling
in time and in gain can miss, so a touch between two samples is still caught (the argument is in
docs/safety.md). Candidates: the full command first; if it touches, the stop (if even that
touches, the stop is sent and reported blocked); else the same path slower (``scales``), all
in one batch, the fastest clear one sent, or the stop.

A point that is already nearer than the inflated footprint at the start (the robot stopped
close to something) only blocks a motion that brings it nearer: the robot may always move away.

Numpy, with the inner loop (:meth:`SweptFootprint._touches`) in C when it was built
(``_cswept.c``: the same answers; ``EMOS_SWEPT=python`` or ``native=False`` turns it off). The
poses are exact arcs (those of :func:`emos.geometry.integrate_pose`, in fewer
array operations) and the base's response to the commands comes from
:meth:`SweptFootprint.response`. What depends on the points alone (sorted by distance, their
homogeneous rows, their distance at the start) is prepared once per scan
(:meth:`SweptFootprint.prepare`, kept by :class:`ScanCache`); every command reuses it.
"""
from __future__ import annotations

import math
import os
from collections.abc import Callable
from types import ModuleType

import attrs
import numpy as np

from emos.config.validators import in_range

from ..robot import RobotConfig, RobotGeometry

__all__ = ["ScanCache", "SweptConfig", "SweptCheck", "SweptFootprint", "SweptPoints"]

_TOL = 1e-3  # m: a point must come this much nearer than it started to count as approached
_COARSE_STRIDE = 4  # poses: the prefilter looks at every 4th pose's centre
_PARTS = 2  # after the shared poses, the rest is looked at in this many spans
_EPS = float(np.finfo(np.float64).eps)  # what np.sinc puts for 0 (0 / 0)


def _load_native() -> ModuleType | None:
    """The C inner loop (``_cswept.c``) if it was built and not turned off with
    ``EMOS_SWEPT=python``; else None (the numpy version alone, the same answers)."""
    if os.environ.get("EMOS_SWEPT", "").lower() == "python":
        return None
    try:
        from emos.actors.nav.safety import _cswept
    except ImportError:  # installed without a C compiler
        return None
    return _cswept


NATIVE = _load_native()


def _scales(value: object) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in value)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        raise ValueError(f"SweptConfig.scales: expected numbers in (0, 1], got {value!r}") from None
    if not out or any(not (0.0 < v <= 1.0) for v in out) or list(out) != sorted(out, reverse=True):
        raise ValueError(f"SweptConfig.scales: expected decreasing numbers in (0, 1] starting at 1, got {value!r}")
    return out


def _window_max(values: np.ndarray, width: int) -> np.ndarray:
    """The running maximum (..., K) of non-negative ``values`` (..., K) over the last ``width``
    entries (fewer at the start), in a fixed handful of whole-array operations (van Herk and
    Gil-Werman): in blocks of ``width``, the maximum from each block's start to an entry and
    from an entry to its block's end; a window spans at most two blocks, so its maximum is the
    latter at its first entry and the former at its last."""
    n = values.shape[-1]
    if width <= 1 or n == 0:
        return np.array(values, dtype=np.float64)
    blocks = -(-n // width)
    padded = np.zeros(values.shape[:-1] + (blocks, width))  # 0: neutral for non-negative values
    padded.reshape(values.shape[:-1] + (blocks * width,))[..., :n] = values
    ahead = np.maximum.accumulate(padded, axis=-1).reshape(values.shape[:-1] + (-1,))
    behind = np.maximum.accumulate(padded[..., ::-1], axis=-1)[..., ::-1].reshape(values.shape[:-1] + (-1,))
    out = ahead[..., :n].copy()  # within the first block: the maximum from the start
    if n >= width:
        np.maximum(out[..., width - 1:], behind[..., :n - width + 1], out=out[..., width - 1:])
    return out


@attrs.define(frozen=True, kw_only=True)
class SweptConfig:
    """The motion model the check is conservative for (defaults: the realistic Jackal of the
    simulator's skid-steer model, see docs/safety.md).

    ``margin`` (m): clearance kept beyond the footprint (range noise, odometry between scans).
    ``latency`` (s): from the scan's time plus its age to the command acting on the wheels.
    ``hold`` (s): how long one command acts before the next replaces it (the command period).
    ``max_braking`` (m/s^2): the body's braking limit (friction); the robot's own ``max_decel``
    is used when lower. ``yaw_lag`` (s): the body's yaw rate lag behind the wheels (the turn
    it keeps after the wheels stop is yaw_rate * yaw_lag). ``yaw_gain_min``: the least fraction of
    the commanded yaw rate the body turns at; ``speed_loss`` (per rad/s): forward speed lost
    while turning (the body then turns tighter than commanded). ``time_step`` (s) between poses;
    yaw gains are sampled from ``gains`` to ``max_gains`` of them, as many as keep what lies between
    two samples within ``gain_gap`` (m, then added to the inflation); ``scales``: the slower
    versions of a command tried. ``hysteresis`` (m): a command that moves is let through only
    with this much clearance beyond ``margin``, a stop with ``margin`` alone, so that the next
    scan's range noise does not turn the stop the last check vouched for into "blocked" (0 by
    default: 0.015 m made the BARN runs slower, 14.9 s against 9.7 s mean, for no fewer stops;
    docs/safety.md)."""

    margin: float = attrs.field(default=0.02, converter=float, validator=in_range(min_value=0.0, max_value=1.0))
    latency: float = attrs.field(default=0.15, converter=float, validator=in_range(min_value=0.0, max_value=2.0))
    hold: float = attrs.field(default=0.1, converter=float, validator=in_range(min_value=0.001, max_value=2.0))
    max_braking: float = attrs.field(default=4.9, converter=float, validator=in_range(min_value=0.01, max_value=1e3))
    yaw_lag: float = attrs.field(default=0.4, converter=float, validator=in_range(min_value=0.0, max_value=5.0))
    yaw_gain_min: float = attrs.field(default=0.6, converter=float, validator=in_range(min_value=0.05, max_value=1.0))
    speed_loss: float = attrs.field(default=0.07, converter=float, validator=in_range(min_value=0.0, max_value=0.2))
    time_step: float = attrs.field(default=0.02, converter=float, validator=in_range(min_value=0.002, max_value=0.2))
    gains: int = attrs.field(default=2, validator=in_range(min_value=2, max_value=64))
    max_gains: int = attrs.field(default=5, validator=in_range(min_value=2, max_value=64))
    gain_gap: float = attrs.field(default=0.01, converter=float, validator=in_range(min_value=0.001, max_value=0.5))
    scales: tuple[float, ...] = attrs.field(default=(1.0, 0.6, 0.3, 0.15), converter=_scales)
    hysteresis: float = attrs.field(default=0.0, converter=float, validator=in_range(min_value=0.0, max_value=0.5))


@attrs.define(frozen=True)
class SweptCheck:
    """``scale``: the factor the command was multiplied by (1: as asked, 0: stop); ``clearance``
    (m): the least distance of a point to the footprint along the chosen motion
    (inf: no point near); ``blocked``: even a stop touches (a point came into reach unseen)."""

    scale: float
    clearance: float
    blocked: bool = False

    @property
    def stopped(self) -> bool:
        return self.scale == 0.0


FREE = SweptCheck(1.0, math.inf)


class SweptFootprint:
    """The check for one robot. ``check(command, previous, points, lead)`` -> :class:`SweptCheck`."""

    def __init__(self, robot: RobotConfig, config: SweptConfig | None = None, *, native: bool | None = None) -> None:
        """``native``: use the C inner loop (None: if it was built, False: never, True: it must be)."""
        if native and NATIVE is None:
            raise RuntimeError("SweptFootprint(native=True): the C inner loop actors/nav/safety/_cswept.c was not built "
                               "(no C compiler at install) or EMOS_SWEPT=python turned it off")
        self._native = NATIVE if native is not False else None
        self.robot = robot
        self.config = config or SweptConfig()
        p = robot.geometry_params
        self._box = robot.geometry_type is RobotGeometry.Type.BOX
        # Half extents of the box; other shapes use their bounding circle (conservative).
        self._half = (0.5 * float(p[0]), 0.5 * float(p[1])) if self._box else (robot.radius, robot.radius)
        self._radius = robot.radius
        # The footprint's farthest point from the centre (what the sampling bounds turn).
        self._reach = math.hypot(*self._half) if self._box else robot.radius
        self._radius = max(self._radius, self._reach)  # the prefilters' bound must cover it
        self._half_col = np.array(self._half).reshape(2, 1)
        cfg = self.config
        lim = robot.ctrl_vx_limits, robot.ctrl_vy_limits, robot.ctrl_omega_limits
        # Braking at the lower of the robot's limit and the body's (the slowest it may brake).
        self._decel = np.array([min(lim[0].max_decel, cfg.max_braking), min(lim[1].max_decel, cfg.max_braking),
                                lim[2].max_decel])
        self._lag = int(math.ceil(cfg.yaw_lag / cfg.time_step - 1e-9))  # time steps a turn's yaw rate holds
        self._ramps: dict[int, np.ndarray] = {}
        # What every check needs of the configuration, made once (a check is a few hundred
        # microseconds, so a handful of small arrays made per call is a measurable share).
        self._scales = np.array(cfg.scales + (0.0,))  # the candidates: as asked, slower, the stop
        self._hysteresis = np.where(np.arange(len(self._scales)) == len(self._scales) - 1, 0.0, cfg.hysteresis)
        self._stop_lag = np.array([0.0, 0.0, cfg.yaw_lag])
        self._hold_steps = max(1, int(math.ceil(cfg.hold / cfg.time_step - 1e-9)))
        # What the C inner loop needs of the footprint and this module's constants.
        self._native_shape = (int(self._box), self._half[0], self._half[1], self._radius, cfg.margin,
                              _COARSE_STRIDE, _PARTS, _TOL)

    # -- prediction ---------------------------------------------------------------------------
    def pipe(self, previous: np.ndarray, lead: float, history: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """Twists (n1, 3) from the scan's time to when a command sent now acts: one per
        ``time_step`` over ``lead + latency`` s. Each is the command that was sent ``latency``
        before (``history``: send times relative to now, increasing, and the commands); without
        a history, or before its first entry, ``previous``."""
        cfg = self.config
        dt = cfg.time_step
        n1 = self._pipe_steps(lead)
        prev = np.asarray(previous, dtype=np.float64).reshape(3)
        if history is None or len(history[0]) == 0 or n1 == 0:
            out = np.empty((n1, 3))
            out[:] = prev
            return out
        times, commands = np.asarray(history[0], dtype=np.float64), np.asarray(history[1], dtype=np.float64).reshape(-1, 3)
        acting = -max(lead, 0.0) + np.arange(n1) * dt - cfg.latency  # when what acts at each step was sent
        # A step's command is the one sent last before its start, or the next one if that is
        # sooner within the step (of the two the robot drives both over the step).
        # searchsorted gives 0..len(times), so less one only the lower bound needs clipping.
        first = np.maximum(np.searchsorted(times, acting, side="right") - 1, 0)
        last = np.maximum(np.searchsorted(times, acting + dt, side="left") - 1, 0)
        a, b = commands[first], commands[last]
        return np.where(np.abs(b) > np.abs(a), b, a)

    def _pipe_steps(self, lead: float) -> int:
        """How many time steps the pipe (:meth:`pipe`) lasts."""
        cfg = self.config
        return int(math.ceil((max(lead, 0.0) + cfg.latency) / cfg.time_step - 1e-9))

    def twists(self, command: np.ndarray, previous: np.ndarray, lead: float, scales: np.ndarray,
               history: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """Body twists (C, K, 3), one per ``time_step``, for the command scaled by each of ``scales``:
        what the base does with the commands of :meth:`pipe`, then the candidate for ``hold`` s,
        then zero, through :meth:`response`."""
        cfg = self.config
        dt = cfg.time_step
        cmd = np.asarray(command, dtype=np.float64).reshape(3)
        prev = np.asarray(previous, dtype=np.float64).reshape(3)
        targets = scales[:, None] * cmd[None, :]
        pipe = self.pipe(prev, lead, history)
        n1 = pipe.shape[0]
        n2 = self._hold_steps
        # Long enough to stop from the fastest twist anywhere in the sequence.
        fastest = np.abs(cmd) * float(scales.max())  # the largest |scale * command| per axis
        if n1:
            np.maximum(fastest, np.abs(prev) if history is None else np.abs(pipe).max(axis=0), out=fastest)
        n3 = int(math.ceil(float((fastest / self._decel + self._stop_lag).max()) / dt - 1e-9)) + 2
        commanded = np.zeros((len(scales), n1 + n2 + n3, 3))
        commanded[:, :n1] = pipe
        commanded[:, n1:n1 + n2] = targets[:, None, :]
        return self.response(commanded)

    def response(self, commanded: np.ndarray) -> np.ndarray:
        """The body twists (..., K, 3) a base makes of commanded twists (..., K, 3), one per
        ``time_step``, as far as they can reach: speeding up at once (no base is faster), slowing
        down no faster than the braking limits, and the yaw rate of a turn going on for
        ``yaw_lag`` s after its command dropped (a skid-steer body keeps turning while its wheels
        break their sideways grip). Per axis and direction: v_k = max over j <= k of
        (c_j - decel * (k - j) * dt), the slowest decay from every earlier command."""
        k = self._ramp(commanded.shape[-2])  # (K, 3): decel * step * dt
        lag = self._lag
        parts = []
        for c in (np.maximum(commanded, 0.0), np.maximum(-commanded, 0.0)):
            if not c.any():  # nothing this way (most sequences go forward only)
                parts.append(c)
                continue
            if lag:
                # The yaw rate: the largest command of the last yaw_lag s holds before it decays.
                c[..., 2] = _window_max(c[..., 2], lag + 1)
            parts.append(np.maximum.accumulate(c + k, axis=-2) - k)
        forward, backward = parts
        # A base going one way brakes through zero before it goes the other way.
        return np.where(forward > 1e-12, forward, -backward)

    def _ramp(self, steps: int) -> np.ndarray:
        """(steps, 3): what braking takes off each axis after 0, 1, ... time steps (cached per length)."""
        ramp = self._ramps.get(steps)
        if ramp is None:
            ramp = np.arange(steps, dtype=np.float64)[:, None] * self.config.time_step * self._decel
            self._ramps[steps] = ramp
        return ramp

    def gain_values(self, twists: np.ndarray) -> np.ndarray:
        """The yaw gains sampled: from ``yaw_gain_min`` to the tightest turn the speed loss allows."""
        return self._gain_values(twists, None)

    def _gain_values(self, twists: np.ndarray, sensitivity: np.ndarray | None) -> np.ndarray:
        """:meth:`gain_values` with :meth:`_gain_sensitivity` of ``twists`` given (None: computed)."""
        cfg = self.config
        w = twists[..., 2]
        w_max = float(np.abs(w).max()) if twists.size else 0.0
        hi = 1.0 / max(1.0 - cfg.speed_loss * w_max, 0.5)
        if not (np.abs(twists[..., :2]) > 1e-9).any() and ((w >= 0.0).all() or (w <= 0.0).all()):
            # A rotation in place one way: a smaller gain turns through a part of the same sweep.
            return np.array([hi])
        # Enough gains that what lies between two of them stays within gain_gap (see inflation()).
        if sensitivity is None:
            sensitivity = self._gain_sensitivity(twists)
        need = (hi - cfg.yaw_gain_min) * float(sensitivity.max()) / (2.0 * cfg.gain_gap)
        count = int(min(max(cfg.gains, 1 + math.ceil(need)), cfg.max_gains))
        gains = cfg.yaw_gain_min + np.arange(count) * ((hi - cfg.yaw_gain_min) / (count - 1))  # np.linspace, cheaper
        gains[-1] = hi
        return gains

    def poses(self, twists: np.ndarray, gains: np.ndarray) -> np.ndarray:
        """Poses (C, G, K + 1, 3) from the start pose (0, 0, 0) for every twist sequence and gain.

        Each step is the exact arc of its constant twist (as :func:`emos.geometry.integrate_pose`):
        the body's velocity turns uniformly through ``dth``, so the step's displacement is the
        chord ``dt sinc(dth / 2)`` along the heading halfway through it (sinc(x) = sin x / x)."""
        dt = self.config.time_step
        n_c, k = twists.shape[:2]
        dth = twists[:, None, :, 2] * (gains[None, :, None] * dt)  # (C, G, K) heading change per step
        out = np.zeros((n_c, len(gains), k + 1, 3))
        heading = np.cumsum(dth, axis=-1, out=out[..., 1:, 2])
        mid = heading - 0.5 * dth  # the heading halfway through each step
        # sinc(dth / 2) as numpy's np.sinc(x) = sin(pi x) / (pi x) computes it, the same
        # operations without its wrapper's overhead.
        half = math.pi * (dth * (0.5 / math.pi))
        half = np.where(half, half, _EPS)
        chord = np.sin(half)
        chord /= half
        chord *= dt
        c, s = np.cos(mid), np.sin(mid)
        c *= chord
        s *= chord
        vx, vy = twists[:, None, :, 0], twists[:, None, :, 1]
        if vy.any():
            np.cumsum(c * vx - s * vy, axis=-1, out=out[..., 1:, 0])
            np.cumsum(s * vx + c * vy, axis=-1, out=out[..., 1:, 1])
        else:  # no sideways velocity (a differential drive): the same sums without its zero terms
            c *= vx
            s *= vx
            np.cumsum(c, axis=-1, out=out[..., 1:, 0])
            np.cumsum(s, axis=-1, out=out[..., 1:, 1])
        return out

    def _gain_sensitivity(self, twists: np.ndarray, speed: np.ndarray | None = None) -> np.ndarray:
        """Per sequence (...,): a bound B of how far any footprint point moves per unit of yaw
        gain, at any time of the sequence: B = integral |v| |Theta| dt + R_f max |Theta|
        (Theta: the heading at gain 1, R_f: the footprint's farthest point from the centre)."""
        dt = self.config.time_step
        end = np.abs(np.cumsum(twists[..., 2], axis=-1) * dt)  # |Theta| at the end of each step
        # Theta is linear over a step, so its largest magnitude there is at one of its ends (the
        # first step starts at 0).
        theta = end.copy()
        np.maximum(end[..., 1:], end[..., :-1], out=theta[..., 1:])
        if speed is None:
            speed = np.hypot(twists[..., 0], twists[..., 1])
        top = theta.max(axis=-1) if theta.shape[-1] else np.zeros(theta.shape[:-1])
        bound: np.ndarray = (speed * theta).sum(axis=-1) * dt + self._reach * top
        return bound

    def inflation(self, twists: np.ndarray, gains: np.ndarray) -> np.ndarray:
        """Per candidate (C,): ``margin`` + what time sampling can miss + what gain sampling can miss.

        The distance of a fixed point to the footprint changes by at most the largest
        displacement of a footprint point, and the footprint is rigid: over a time_step that is
        at most (|v| + |w| R_f) dt (R_f: its farthest point from the centre); any instant is
        within dt / 2 of a sample. A gain between two samples dg apart is within dg / 2 of one
        of them, and a footprint point moves per unit of gain by at most B
        (:meth:`_gain_sensitivity`): d/dg of the position is the integral of v Theta turned a
        quarter, of the body's turn Theta R_f. See docs/safety.md.
        """
        return self._inflation(twists, gains, self._gain_sensitivity(twists), np.hypot(twists[..., 0], twists[..., 1]))

    def _inflation(self, twists: np.ndarray, gains: np.ndarray, sensitivity: np.ndarray, speed: np.ndarray) -> np.ndarray:
        """:meth:`inflation` with :meth:`_gain_sensitivity` and the linear speeds (C, K) given."""
        cfg = self.config
        dt = cfg.time_step
        g_hi = float(gains.max())
        turn = np.abs(twists[..., 2]) * g_hi
        time_gap = 0.5 * (speed + turn * self._reach).max(axis=1) * dt
        dg = float(gains[1] - gains[0]) if len(gains) > 1 else 0.0
        gain_gap = 0.5 * dg * sensitivity
        total: np.ndarray = cfg.margin + time_gap + gain_gap
        return total

    # -- the check ----------------------------------------------------------------------------
    def clearance(self, poses: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Signed distance (..., N) of each point to the footprint at each pose (..., 3), m,
        negative inside (the box's exact distance; other shapes: their bounding circle's)."""
        x, y, th = poses[..., 0:1], poses[..., 1:2], poses[..., 2:3]
        dx = points[:, 0] - x
        dy = points[:, 1] - y
        c, s = np.cos(th), np.sin(th)
        bx = c * dx + s * dy
        by = c * dy - s * dx
        if self._box:
            qx = np.abs(bx) - self._half[0]
            qy = np.abs(by) - self._half[1]
            box: np.ndarray = np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0)) + np.minimum(np.maximum(qx, qy), 0.0)
            return box
        circle: np.ndarray = np.hypot(bx, by) - self._radius
        return circle

    def prepare(self, points: np.ndarray | SweptPoints) -> SweptPoints:
        """What the check needs of a set of obstacle points (N, 2) that depends on the points
        alone, computed once (the DriveManager does it once per scan, and every command until the
        next scan reuses it): the finite points sorted by their distance from the centre, that distance
        squared, the homogeneous rows (x, y, 1) that put them in any pose's frame by one product,
        and their signed distance to the footprint at the start pose."""
        if isinstance(points, SweptPoints) and points.footprint is self:
            return points
        raw = points.points if isinstance(points, SweptPoints) else points
        pts = np.asarray(raw, dtype=np.float64).reshape(-1, 2)
        finite = np.isfinite(pts).all(axis=1)
        if not finite.all():  # a NaN or inf point is no obstacle; kept, it would make every clearance NaN
            pts = pts[finite]
        norm2 = np.einsum("ij,ij->i", pts, pts)
        order = np.argsort(norm2, kind="stable")
        pts, norm2 = pts[order], norm2[order]
        homog = np.empty((3, len(pts)))
        homog[:2] = pts.T
        homog[2] = 1.0
        start = self.clearance(np.zeros(3), pts) if len(pts) else np.zeros(0)
        return SweptPoints(self, pts, norm2, homog, start)

    def check(self, command: np.ndarray, previous: np.ndarray, points: np.ndarray | SweptPoints, lead: float = 0.0,
              history: tuple[np.ndarray, np.ndarray] | None = None) -> SweptCheck:
        """Scale ``command`` (vx, vy, w) so that its predicted sweep, then a stop, touches no point.

        ``previous``: the command sent last (the base executes it once the latency has passed);
        ``points`` (N, 2) obstacle points in the robot frame of the pose they were seen from, or
        what :meth:`prepare` made of them (the same answer, without redoing the per-scan work);
        ``lead`` (s): how long ago that was; ``history``: (send times relative to now, commands)
        of the commands sent over the last ``lead + latency`` s, which drive the robot until
        this one acts (see :meth:`pipe`).
        """
        cmd = np.asarray(command, dtype=np.float64).reshape(3)
        prev = np.asarray(previous, dtype=np.float64).reshape(3)
        scan = self.prepare(points)
        if len(scan.norm2) == 0:
            return FREE  # nothing to touch
        still = not (abs(cmd).max() > 1e-9 or abs(prev).max() > 1e-9)
        if still and (history is None or not (np.abs(self.pipe(prev, lead, history)) > 1e-9).any()):
            return FREE  # standing still, and staying so
        cfg = self.config
        scales = self._scales
        tw = self.twists(cmd, prev, lead, scales, history)
        speed = np.hypot(tw[..., 0], tw[..., 1])  # (C, K)
        sensitivity = self._gain_sensitivity(tw, speed)
        gains = self._gain_values(tw, sensitivity)
        inflate = self._inflation(tw, gains, sensitivity, speed)
        # Only points the footprint can reach: within the bounding radius (plus inflation) of
        # the centre's path, which stays within the path length of the start. The points are
        # sorted by distance from the centre, so those are a prefix.
        reach = float(speed.sum(axis=1).max()) * cfg.time_step * (1.0 + 1e-6)
        n = int(np.searchsorted(scan.norm2, (self._radius + float(inflate.max()) + reach) ** 2, side="right"))
        if n == 0:
            return FREE
        homog, norm2, start = scan.homog[:, :n], scan.norm2[:n], scan.start[:n]
        step = speed.max(axis=1) * cfg.time_step * _COARSE_STRIDE  # (C,) centre travel between coarse poses

        hysteresis = self._hysteresis
        limit = inflate + hysteresis
        # Poses after a candidate's body has stopped repeat its last one: checked once.
        size = np.abs(tw)
        moving = np.maximum(np.maximum(size[..., 0], size[..., 1]), size[..., 2]) > 1e-12  # (C, K)
        ends = np.where(moving.any(axis=1), tw.shape[1] - np.argmax(moving[:, ::-1], axis=1), 0) + 1

        # The first poses, while the pipe drives the robot, are the same for every candidate
        # (the base's response is causal): a touch there within every candidate's limit is
        # one that even a stop makes.
        shared, shared_limit = self._pipe_steps(lead), float(limit.min())

        clear_to = -1.0  # the shared poses are known clear within this limit

        def touches(which: list[int], decisive: int | None = None) -> list[tuple[bool, float, bool] | None]:
            """The candidates ``which`` in one batch: (touches, clearance beyond the margin,
            touches within the shared poses) each."""
            nonlocal clear_to
            k1 = int(max(ends[which]))
            poses = self.poses(tw[which, :k1 - 1], gains) if k1 > 1 else np.zeros((len(which), len(gains), 1, 3))
            if 0 < shared < k1 - 1 and float(limit[which].max()) <= clear_to:
                # Shared poses already found clear within a limit at least as large: from the
                # last of them on (its clearance then counts from there).
                found = self._touches(poses[:, :, shared:], homog, norm2, start, limit[which], step[which], decisive=decisive)
            else:
                found = self._touches(poses, homog, norm2, start, limit[which], step[which], shared, shared_limit, decisive)
                if found[0] is not None and len(which) == 1 and found[0][3]:
                    clear_to = float(limit[which[0]])
            return [None if f is None else (f[0], f[1] + float(hysteresis[i]), f[2]) for f, i in zip(found, which)]

        # The command as asked first (the usual answer); if it touches, the stop and the slower
        # versions together in one batch (one batch's fixed work instead of two): if even the
        # stop touches, nothing slower helps (the batch ends as soon as it does), else the
        # fastest clear slower one is sent (each answer is checked, none is inferred from another).
        first = touches([0])[0]
        if first is None:
            return FREE
        if not first[0]:
            return SweptCheck(1.0, first[1])
        if first[2]:  # the stop's own poses touch: no need to roll it out
            return SweptCheck(0.0, first[1], blocked=True)
        slower = list(range(1, len(scales) - 1))
        stop, *rest = touches([len(scales) - 1] + slower, decisive=0)
        if stop is not None and stop[0]:
            return SweptCheck(0.0, stop[1], blocked=True)
        for i, found in zip(slower, rest):
            if found is None or not found[0]:
                return SweptCheck(float(scales[i]), math.inf if found is None else found[1])
        return SweptCheck(0.0, math.inf if stop is None else stop[1])

    def _touches(self, poses: np.ndarray, homog: np.ndarray, norm2: np.ndarray, start: np.ndarray,
                 limits: np.ndarray, steps: np.ndarray, shared: int = -1,
                 shared_limit: float = 0.0, decisive: int | None = None) -> list[tuple[bool, float, bool, bool] | None]:
        """Per candidate of ``poses`` (C, G, K + 1, 3): does it bring a point within its
        ``limits`` entry of the footprint (and nearer than it started)? (touches, clearance
        beyond the margin, a touch within ``shared_limit`` at one of the first ``shared`` + 1
        poses, those poses clear within the candidate's limit), or None when no point comes
        near it. ``homog`` (3, N): the points' rows x, y, 1; ``norm2`` (N,): their squared
        distance from the start pose's centre; ``start`` (N,): their distance to the footprint there.
        ``decisive``: a candidate whose touch decides the batch (the stop: then nothing slower
        is sent), so the rest is skipped once it touches too.

        The poses are taken in time order in a few spans (the shared ones first), each against
        only the points near it, and the rest is skipped once every candidate touches (their
        clearance is then the least seen so far)."""
        if self._native is not None:  # the same steps in C (_cswept.c)
            found: list[tuple[bool, float, bool, bool] | None] = self._native.touches(
                poses, homog, norm2, start, limits, steps, shared, shared_limit, -1 if decisive is None else decisive,
                self._native_shape)
            return found
        n_c, n_g, k1, _ = poses.shape
        stride = _COARSE_STRIDE
        # A point within d of the footprint lies within R + d of the centre, so within that plus
        # the travel between coarse poses of a coarse pose's centre; coarse pose j covers poses
        # stride * j .. stride * j + stride - 1.
        centres = poses[:, :, ::stride, :2]  # (C, G, J, 2)
        n_j = centres.shape[2]
        r = self._radius + limits + steps  # (C,)
        # Squared distances less |p|^2 by one product: (-2 cx, -2 cy, |c|^2) . (px, py, 1)
        # (p: the points, c: the centres).
        rows = np.empty((n_c, n_g, n_j, 3))
        np.multiply(centres, -2.0, out=rows[..., :2])
        np.einsum("cgjk,cgjk->cgj", centres, centres, out=rows[..., 2])
        d2 = (rows.reshape(-1, 3) @ homog).reshape(n_c, n_g, n_j, -1)  # (C, G, J, N)
        close = d2.min(axis=1) <= (r * r)[:, None, None] - norm2  # (C, J, N)
        near_any = close.any(axis=1)  # (C, N)
        out: list[tuple[bool, float, bool, bool] | None] = [None] * n_c
        if not near_any.any():
            return out
        # Every pose's frame once: rows (c, s, -(c x + s y)) and (-s, c, s x - c y) give a
        # point's body x and y at the pose by one product with its (x, y, 1).
        c, s = np.cos(poses[..., 2]), np.sin(poses[..., 2])
        x, y = poses[..., 0], poses[..., 1]
        frames = np.empty((n_c, n_g, k1, 2, 3))
        frames[..., 0, 0] = c
        frames[..., 0, 1] = s
        frames[..., 0, 2] = -(c * x + s * y)
        frames[..., 1, 0] = -s
        frames[..., 1, 1] = c
        frames[..., 1, 2] = s * x - c * y
        # Spans of coarse poses: the shared ones (the pipe), then the rest in parts.
        cut = min(max(shared, 0) // stride + 1, n_j)
        edges = [0] + [cut + ((n_j - cut) * i + _PARTS - 1) // _PARTS for i in range(_PARTS + 1)]
        spans = [(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]
        # Per span, the points near any of its coarse poses (of any candidate and gain).
        span_points = np.logical_or.reduceat(close.any(axis=0), [a for a, _ in spans], axis=0)  # (spans, N)
        # Touching: within the limit and nearer than the point started.
        threshold = np.minimum(limits[:, None], start - _TOL)  # (C, N)
        hit = np.zeros(n_c, dtype=bool)
        early = head_hit = hit
        lows = []
        for (a, b), near_span in zip(spans, span_points):
            cand = np.flatnonzero(near_span)
            if cand.size == 0:
                continue
            head = shared + 1 if a == 0 and shared >= 0 else 0
            # (C, n) each: the least distance over the span's poses, and over the shared ones
            least, least_head = self._least_distance(frames[:, :, a * stride:b * stride], homog[:, cand], head)
            lows.append(least.min(axis=1))
            thr = threshold[:, cand]
            hit = hit | np.any(least < thr, axis=1)
            if least_head is not None:
                early = np.any(least_head < np.minimum(shared_limit, start[cand] - _TOL), axis=1)
                head_hit = np.any(least_head < thr, axis=1)
            if hit.all() or (decisive is not None and hit[decisive]):
                break
        low = (np.minimum.reduce(lows) if len(lows) > 1 else lows[0] if lows else np.full(n_c, math.inf)) - limits + self.config.margin
        # The first span, which holds the shared poses, is always looked at (or no point is near it).
        head_clear = ~head_hit if shared >= 0 else np.zeros(n_c, dtype=bool)
        for i in np.flatnonzero(near_any.any(axis=1)):
            out[i] = (bool(hit[i]), float(low[i]), bool(early[i]), bool(head_clear[i]))
        return out

    def _least_distance(self, frames: np.ndarray, homog: np.ndarray, head: int = 0) -> tuple[np.ndarray, np.ndarray | None]:
        """The least signed distance (C, n) of each point to the footprint over the poses of
        each candidate (negative: inside at some pose), and the same over the first ``head``
        poses (None when 0). ``frames`` (C, G, k, 2, 3): each pose's rows that give a point's body
        x and y from its (x, y, 1), ``homog`` (3, n): the points' rows x, y, 1. :meth:`clearance`'s
        distance; for a box without a square root per pose: the least squared distance outside,
        its root taken once per point."""
        n_c, n_g, k = frames.shape[:3]
        body = (frames.reshape(-1, 3) @ homog).reshape(n_c, n_g, k, 2, -1)  # (C, G, k, 2, n)
        if not self._box:
            circle = np.hypot(body[..., 0, :], body[..., 1, :]) - self._radius
            return np.min(circle, axis=(1, 2)), (np.min(circle[:, :, :head], axis=(1, 2)) if head else None)
        q = np.abs(body)
        q -= self._half_col  # beyond the half extents (negative: within)
        # Both per pose in one array, so that each minimum below is one reduction:
        # [0] the depth (negative inside the box: minus the depth), [1] the squared distance
        # outside (0 inside).
        both = np.empty_like(q)
        np.maximum(q[..., 0, :], q[..., 1, :], out=both[..., 0, :])
        np.maximum(q, 0.0, out=q)
        q *= q
        np.add(q[..., 0, :], q[..., 1, :], out=both[..., 1, :])
        if not head or head >= k:
            whole = _signed(both.min(axis=(1, 2)))
            return whole, (whole if head else None)
        # The first poses' least once, and the whole sequence's from it and the rest's (the
        # same minima as reducing the whole again).
        first = both[:, :, :head].min(axis=(1, 2))  # (C, 2, n)
        rest = np.minimum(first, both[:, :, head:].min(axis=(1, 2)))
        return _signed(rest), _signed(first)


def _signed(least: np.ndarray) -> np.ndarray:
    """The signed distance (C, n) from the least depth and least squared distance outside (C, 2, n)
    of a point over some poses: inside at one of them (negative depth), the deepest; else the
    root of the least square. Inside at some pose, the least square is 0, so the sum is exact."""
    out: np.ndarray = np.sqrt(least[:, 1])
    out += np.minimum(least[:, 0], 0.0)
    return out


@attrs.define(frozen=True, eq=False)
class SweptPoints:
    """Obstacle points prepared for one :class:`SweptFootprint` (:meth:`SweptFootprint.prepare`):
    ``points`` (N, 2) sorted by distance from the centre, ``norm2`` that distance squared,
    ``homog`` (3, N) the rows x, y, 1, ``start`` the signed distance of each to the footprint
    at the start pose. Made once per scan and read only."""

    footprint: SweptFootprint
    points: np.ndarray
    norm2: np.ndarray
    homog: np.ndarray
    start: np.ndarray

    def __len__(self) -> int:
        return len(self.norm2)


class ScanCache:
    """The prepared points of the latest scan, rebuilt only when a new scan (or a new ``extra``
    key, e.g. whether the robot's pose was known) comes: ``get(scan_message, extra, build)``
    returns what ``build()`` made for that message. Messages are compared by identity (a
    component keeps the latest message object until the next arrives); None is never reused."""

    def __init__(self) -> None:
        self._key: object = None
        self._extra: object = None
        self._value: SweptPoints | None = None

    def get(self, message: object, extra: object, build: Callable[[], SweptPoints]) -> SweptPoints:
        if self._value is None or message is None or message is not self._key or extra != self._extra:
            self._value = build()
            self._key, self._extra = message, extra
        return self._value

    def clear(self) -> None:
        self._key, self._extra, self._value = None, None, None
