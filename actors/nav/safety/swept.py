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

Pure numpy; the poses come from :func:`emos.geometry.integrate_pose` (exact arcs) and the
base's response to the commands from :meth:`SweptFootprint.response`.
"""
from __future__ import annotations

import math

import attrs
import numpy as np

from emos.config.validators import in_range
from emos.geometry import integrate_pose

from ..robot import RobotConfig, RobotGeometry

__all__ = ["SweptConfig", "SweptCheck", "SweptFootprint"]

_TOL = 1e-3  # m: a point must come this much nearer than it started to count as approached
_COARSE_STRIDE = 4  # poses: the prefilter looks at every 4th pose's centre


def _scales(value: object) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in value)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        raise ValueError(f"SweptConfig.scales: expected numbers in (0, 1], got {value!r}") from None
    if not out or any(not (0.0 < v <= 1.0) for v in out) or list(out) != sorted(out, reverse=True):
        raise ValueError(f"SweptConfig.scales: expected decreasing numbers in (0, 1] starting at 1, got {value!r}")
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

    def __init__(self, robot: RobotConfig, config: SweptConfig | None = None) -> None:
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
        cfg = self.config
        lim = robot.ctrl_vx_limits, robot.ctrl_vy_limits, robot.ctrl_omega_limits
        # Braking at the lower of the robot's limit and the body's (the slowest it may brake).
        self._decel = np.array([min(lim[0].max_decel, cfg.max_braking), min(lim[1].max_decel, cfg.max_braking),
                                lim[2].max_decel])

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
            return np.broadcast_to(prev, (n1, 3))
        times, commands = np.asarray(history[0], dtype=np.float64), np.asarray(history[1], dtype=np.float64).reshape(-1, 3)
        acting = -max(lead, 0.0) + np.arange(n1) * dt - cfg.latency  # when what acts at each step was sent
        # A step's command is the one sent last before its start, or the next one if that is
        # sooner within the step (of the two the robot drives both over the step).
        first = np.clip(np.searchsorted(times, acting, side="right") - 1, 0, len(times) - 1)
        last = np.clip(np.searchsorted(times, acting + dt, side="left") - 1, 0, len(times) - 1)
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
        n2 = max(1, int(math.ceil(cfg.hold / dt - 1e-9)))
        # Long enough to stop from the fastest twist anywhere in the sequence.
        fastest = np.max(np.abs(np.concatenate([pipe, targets])), axis=0) if n1 else np.max(np.abs(targets), axis=0)
        n3 = int(math.ceil(float(np.max(fastest / self._decel + np.array([0.0, 0.0, cfg.yaw_lag]))) / dt - 1e-9)) + 2
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
        cfg = self.config
        dt = cfg.time_step
        k = np.arange(commanded.shape[-2], dtype=np.float64)[:, None] * dt * self._decel  # (K, 3)
        lag = int(math.ceil(cfg.yaw_lag / dt - 1e-9))
        parts = []
        for sign in (1.0, -1.0):
            c = np.maximum(sign * commanded, 0.0)
            if not c.any():  # nothing this way (most sequences go forward only)
                parts.append(c)
                continue
            if lag:
                # The yaw rate: the largest command of the last yaw_lag s holds before it decays.
                padded = np.concatenate([np.zeros(c.shape[:-2] + (lag, 3)), c], axis=-2)
                windows = np.lib.stride_tricks.sliding_window_view(padded[..., 2], lag + 1, axis=-1)
                c[..., 2] = windows.max(axis=-1)
            parts.append(np.maximum.accumulate(c + k, axis=-2) - k)
        forward, backward = parts
        # A base going one way brakes through zero before it goes the other way.
        return np.where(forward > 1e-12, forward, -backward)

    def gain_values(self, twists: np.ndarray) -> np.ndarray:
        """The yaw gains sampled: from ``yaw_gain_min`` to the tightest turn the speed loss allows."""
        cfg = self.config
        w_max = float(np.max(np.abs(twists[..., 2]))) if twists.size else 0.0
        hi = 1.0 / max(1.0 - cfg.speed_loss * w_max, 0.5)
        w = twists[..., 2]
        if not np.any(np.abs(twists[..., :2]) > 1e-9) and (np.all(w >= 0.0) or np.all(w <= 0.0)):
            # A rotation in place one way: a smaller gain turns through a part of the same sweep.
            return np.array([hi])
        # Enough gains that what lies between two of them stays within gain_gap (see inflation()).
        need = (hi - cfg.yaw_gain_min) * float(np.max(self._gain_sensitivity(twists))) / (2.0 * cfg.gain_gap)
        count = int(min(max(cfg.gains, 1 + math.ceil(need)), cfg.max_gains))
        return np.linspace(cfg.yaw_gain_min, hi, count)

    def poses(self, twists: np.ndarray, gains: np.ndarray) -> np.ndarray:
        """Poses (C, G, K + 1, 3) from the start pose (0, 0, 0) for every twist sequence and gain."""
        dt = self.config.time_step
        tw = np.repeat(twists[:, None], len(gains), axis=1)  # (C, G, K, 3)
        tw[..., 2] *= gains[None, :, None]
        heading = np.concatenate([np.zeros(tw.shape[:2] + (1,)), np.cumsum(tw[..., 2] * dt, axis=-1)], axis=-1)
        start = np.zeros(tw.shape)
        start[..., 2] = heading[..., :-1]
        step = integrate_pose(start, tw, dt)  # displacement of each step, in the start frame
        out = np.zeros(tw.shape[:2] + (tw.shape[2] + 1, 3))
        out[..., 1:, :2] = np.cumsum(step[..., :2], axis=-2)
        out[..., 2] = heading
        return out

    def _gain_sensitivity(self, twists: np.ndarray) -> np.ndarray:
        """Per sequence (...,): a bound B of how far any footprint point moves per unit of yaw
        gain, at any time of the sequence: B = integral |v| |Theta| dt + R_f max |Theta|
        (Theta: the heading at gain 1, R_f: the footprint's farthest point from the centre)."""
        dt = self.config.time_step
        heading = np.cumsum(twists[..., 2], axis=-1) * dt  # Theta at the end of each step
        before = np.concatenate([np.zeros(heading.shape[:-1] + (1,)), heading[..., :-1]], axis=-1)
        # Theta is linear over a step, so its largest magnitude there is at one of its ends.
        theta = np.maximum(np.abs(heading), np.abs(before))
        speed = np.hypot(twists[..., 0], twists[..., 1])
        top = np.max(theta, axis=-1) if theta.shape[-1] else np.zeros(theta.shape[:-1])
        bound: np.ndarray = np.sum(speed * theta, axis=-1) * dt + self._reach * top
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
        cfg = self.config
        dt = cfg.time_step
        g_hi = float(gains.max())
        speed = np.hypot(twists[..., 0], twists[..., 1])
        turn = np.abs(twists[..., 2]) * g_hi
        time_gap = 0.5 * np.max(speed + turn * self._reach, axis=1) * dt
        dg = float(gains[1] - gains[0]) if len(gains) > 1 else 0.0
        gain_gap = 0.5 * dg * self._gain_sensitivity(twists)
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

    def check(self, command: np.ndarray, previous: np.ndarray, points: np.ndarray, lead: float = 0.0,
              history: tuple[np.ndarray, np.ndarray] | None = None) -> SweptCheck:
        """Scale ``command`` (vx, vy, w) so that its predicted sweep, then a stop, touches no point.

        ``previous``: the command sent last (the base executes it once the latency has passed);
        ``points`` (N, 2) obstacle points in the robot frame of the pose they were seen from;
        ``lead`` (s): how long ago that was; ``history``: (send times relative to now, commands)
        of the commands sent over the last ``lead + latency`` s, which drive the robot until
        this one acts (see :meth:`pipe`).
        """
        cmd = np.asarray(command, dtype=np.float64).reshape(3)
        prev = np.asarray(previous, dtype=np.float64).reshape(3)
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if pts.shape[0] == 0:
            return FREE  # nothing to touch
        still = not (np.any(np.abs(cmd) > 1e-9) or np.any(np.abs(prev) > 1e-9))
        if still and (history is None or not np.any(np.abs(self.pipe(prev, lead, history)) > 1e-9)):
            return FREE  # standing still, and staying so
        scales = np.array(self.config.scales + (0.0,))
        tw = self.twists(cmd, prev, lead, scales, history)
        gains = self.gain_values(tw)
        inflate = self.inflation(tw, gains)
        # Only points the footprint can reach: within the bounding radius (plus inflation) of
        # the centre's path, which stays within the path length of the start.
        speed = np.hypot(tw[..., 0], tw[..., 1])
        reach = float(np.max(np.sum(speed, axis=1))) * self.config.time_step * (1.0 + 1e-6)
        near = np.einsum("ij,ij->i", pts, pts) <= (self._radius + float(inflate.max()) + reach) ** 2
        pts = pts[near]
        if pts.shape[0] == 0:
            return FREE
        start = self.clearance(np.zeros(3), pts)  # (N,)
        step = np.max(speed, axis=1) * self.config.time_step * _COARSE_STRIDE  # (C,) centre travel between coarse poses

        hysteresis = np.where(np.arange(len(scales)) == len(scales) - 1, 0.0, self.config.hysteresis)
        limit = inflate + hysteresis
        # Poses after a candidate's body has stopped repeat its last one: checked once.
        moving = np.any(np.abs(tw) > 1e-12, axis=2)
        ends = np.where(moving.any(axis=1), tw.shape[1] - np.argmax(moving[:, ::-1], axis=1), 0) + 1

        # The first poses, while the pipe drives the robot, are the same for every candidate
        # (the base's response is causal): a touch there within every candidate's limit is
        # one that even a stop makes.
        shared, shared_limit = self._pipe_steps(lead), float(limit.min())

        clear_to = -1.0  # the shared poses are known clear within this limit

        def touches(which: list[int]) -> list[tuple[bool, float, bool] | None]:
            """The candidates ``which`` in one batch: (touches, clearance beyond the margin,
            touches within the shared poses) each."""
            nonlocal clear_to
            k1 = int(max(ends[which]))
            poses = self.poses(tw[which, :k1 - 1], gains) if k1 > 1 else np.zeros((len(which), len(gains), 1, 3))
            if 0 < shared < k1 - 1 and float(limit[which].max()) <= clear_to:
                # Shared poses already found clear within a limit at least as large: from the
                # last of them on (its clearance then counts from there).
                found = self._touches(poses[:, :, shared:], pts, start, limit[which], step[which])
            else:
                found = self._touches(poses, pts, start, limit[which], step[which], shared, shared_limit)
                if found[0] is not None and len(which) == 1 and found[0][3]:
                    clear_to = float(limit[which[0]])
            return [None if f is None else (f[0], f[1] + float(hysteresis[i]), f[2]) for f, i in zip(found, which)]

        # The command as asked first (the usual answer), then the stop: if even that touches,
        # nothing slower helps; then the slower versions together in one batch, the fastest
        # clear one sent (each answer is checked, none is inferred from another).
        first = touches([0])[0]
        if first is None:
            return FREE
        if not first[0]:
            return SweptCheck(1.0, first[1])
        if first[2]:  # the stop's own poses touch: no need to roll it out
            return SweptCheck(0.0, first[1], blocked=True)
        stop = touches([len(scales) - 1])[0]
        if stop is not None and stop[0]:
            return SweptCheck(0.0, stop[1], blocked=True)
        slower = list(range(1, len(scales) - 1))
        for i, found in zip(slower, touches(slower) if slower else []):
            if found is None or not found[0]:
                return SweptCheck(float(scales[i]), math.inf if found is None else found[1])
        return SweptCheck(0.0, math.inf if stop is None else stop[1])

    def _touches(self, poses: np.ndarray, pts: np.ndarray, start: np.ndarray, limits: np.ndarray,
                 steps: np.ndarray, shared: int = -1,
                 shared_limit: float = 0.0) -> list[tuple[bool, float, bool, bool] | None]:
        """Per candidate of ``poses`` (C, G, K + 1, 3): does it bring a point within its
        ``limits`` entry of the footprint (and nearer than it started)? (touches, clearance
        beyond the margin, a touch within ``shared_limit`` at one of the first ``shared`` + 1
        poses, those poses clear within the candidate's limit), or None when no point comes
        near it.

        The poses are taken in time order in a few spans (the shared ones first), each against
        only the points near it, and the rest is skipped once every candidate touches (their
        clearance is then the least seen so far)."""
        n_c, n_g, k1, _ = poses.shape
        stride = _COARSE_STRIDE
        # A point within d of the footprint lies within R + d of the centre, so within that plus
        # the travel between coarse poses of a coarse pose's centre; coarse pose j covers poses
        # stride * j .. stride * j + stride - 1.
        centres = poses[:, :, ::stride, :2]  # (C, G, J, 2)
        r = self._radius + limits + steps  # (C,)
        # Squared distances by one product: |p|^2 + |c|^2 - 2 p.c (p: the points, c: the centres).
        d2 = np.einsum("cgjk,cgjk->cgj", centres, centres)[..., None] - 2.0 * (centres @ pts.T)  # (C, G, J, N)
        close = np.min(d2, axis=1) <= (r * r)[:, None, None] - np.einsum("ij,ij->i", pts, pts)  # (C, J, N)
        near_any = close.any(axis=1)  # (C, N)
        out: list[tuple[bool, float, bool, bool] | None] = [None] * n_c
        if not near_any.any():
            return out
        # Spans of coarse poses: the shared ones (the pipe), then the rest in halves.
        n_j = centres.shape[2]
        cut = min(max(shared, 0) // stride + 1, n_j)
        mid = cut + (n_j - cut + 1) // 2
        spans = [(a, b) for a, b in ((0, cut), (cut, mid), (mid, n_j)) if b > a]
        hit = np.zeros(n_c, dtype=bool)
        early = np.zeros(n_c, dtype=bool)
        head_hit = np.zeros(n_c, dtype=bool)
        low = np.full(n_c, math.inf)
        below = start - _TOL
        for a, b in spans:
            cand = np.nonzero(close[:, a:b].any(axis=(0, 1)))[0]
            if cand.size == 0:
                continue
            span = poses[:, :, a * stride:min(b * stride, k1)]  # (C, G, k, 3)
            d = self._box_distance(span.reshape(-1, 3), pts[cand]).reshape(span.shape[:3] + (len(cand),))
            low = np.minimum(low, np.min(d, axis=(1, 2, 3)) - limits + self.config.margin)
            # Touching: within the limit and nearer than the point started.
            hit |= np.any(d < np.minimum(limits[:, None], below[cand])[:, None, None, :], axis=(1, 2, 3))
            if a == 0 and shared >= 0:
                head = d[:, :, :shared + 1]
                early |= np.any(head < np.minimum(shared_limit, below[cand]), axis=(1, 2, 3))
                head_hit |= np.any(head < np.minimum(limits[:, None], below[cand])[:, None, None, :], axis=(1, 2, 3))
            if hit.all():
                break
        # The first span, which holds the shared poses, is always looked at (or no point is near it).
        head_clear = ~head_hit if shared >= 0 else np.zeros(n_c, dtype=bool)
        for i in range(n_c):
            if near_any[i].any():
                out[i] = (bool(hit[i]), float(low[i]), bool(early[i]), bool(head_clear[i]))
        return out

    def _box_distance(self, poses: np.ndarray, pts: np.ndarray) -> np.ndarray:
        """Distance (M, n) of each point to the footprint at each pose (M, 3), negative inside:
        :meth:`clearance` by one (2M, 2) @ (2, n) product for every point in every body frame."""
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        rot = np.empty((2 * len(poses), 2))
        rot[0::2, 0], rot[0::2, 1], rot[1::2, 0], rot[1::2, 1] = c, s, -s, c
        body = (rot @ pts.T).reshape(len(poses), 2, -1)
        off = rot.reshape(len(poses), 2, 2) @ poses[:, :2, None]  # (M, 2, 1): the pose's own position, turned
        bx = body[:, 0] - off[:, 0]
        by = body[:, 1] - off[:, 1]
        if not self._box:
            circle: np.ndarray = np.hypot(bx, by) - self._radius
            return circle
        qx = np.abs(bx) - self._half[0]
        qy = np.abs(by) - self._half[1]
        box: np.ndarray = np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0)) + np.minimum(np.maximum(qx, qy), 0.0)
        return box
