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
docs/safety.md). Candidates are tried from the full command down: the same path slower
(``scales``), then a stop; the first whose prediction is clear is sent.

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
    max_gains: int = attrs.field(default=8, validator=in_range(min_value=2, max_value=64))
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
        n1 = int(math.ceil((max(lead, 0.0) + cfg.latency) / dt - 1e-9))
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
        dt = cfg.time_step
        turn = float(np.max(np.sum(np.abs(w), axis=-1))) * dt * hi
        length = float(np.max(np.sum(np.hypot(twists[..., 0], twists[..., 1]), axis=-1))) * dt
        need = (hi - cfg.yaw_gain_min) * turn * (length + self._radius + cfg.margin + 0.05) / (2.0 * cfg.gain_gap)
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

    def inflation(self, twists: np.ndarray, gains: np.ndarray) -> np.ndarray:
        """Per candidate (C,): ``margin`` + what time sampling can miss + what gain sampling can miss.

        Between two poses a time_step apart a fixed point moves, in the body frame, by at most
        (|v| + |w| r) dt with r its distance from the centre (<= the bounding radius plus the
        inflation while it can touch); half of that separates any instant from its nearest
        sample. Two neighbouring gains differ in heading by at most dg * W (W = the turn over the
        horizon) and in position by at most dg * W * S (S = the path length); halfway between
        them half of it, plus the heading's effect on the footprint (r * dg * W / 2).
        """
        cfg = self.config
        dt = cfg.time_step
        g_hi = float(gains.max())
        r = self._radius + cfg.margin + 0.05  # generous bound of the reach of a touching point
        speed = np.hypot(twists[..., 0], twists[..., 1])
        turn = np.abs(twists[..., 2]) * g_hi
        time_gap = 0.5 * np.max(speed + turn * r, axis=1) * dt
        dg = float(gains[1] - gains[0]) if len(gains) > 1 else 0.0
        big_w = np.sum(np.abs(twists[..., 2]), axis=1) * dt * g_hi
        length = np.sum(speed, axis=1) * dt
        gain_gap = 0.5 * dg * big_w * (length + r)
        return cfg.margin + time_gap + gain_gap

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
            return np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0)) + np.minimum(np.maximum(qx, qy), 0.0)
        return np.hypot(bx, by) - self._radius

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

        stop_index = len(scales) - 1
        hysteresis = self.config.hysteresis

        def touches(i: int) -> tuple[bool, float] | None:
            extra = 0.0 if i == stop_index else hysteresis
            found = self._touches(self.poses(tw[i:i + 1], gains)[0], pts, start, float(inflate[i]) + extra, float(step[i]))
            return None if found is None else (found[0], found[1] + extra)

        # The command as asked first (the usual answer), then the stop: if even that touches,
        # nothing slower helps; then the slower versions by bisection (a slower one sweeps a
        # part of a faster one's path, so clear is monotone in practice; each answer is checked).
        first = touches(0)
        if first is None:
            return FREE
        if not first[0]:
            return SweptCheck(1.0, first[1])
        stop = touches(len(scales) - 1)
        if stop is not None and stop[0]:
            return SweptCheck(0.0, stop[1], blocked=True)
        best = SweptCheck(0.0, math.inf if stop is None else stop[1])
        lo, hi = 1, len(scales) - 2  # the fastest clear one lies in [lo, hi], or none does
        while lo <= hi:
            mid = (lo + hi) // 2
            found = touches(mid)
            if found is None or not found[0]:
                best = SweptCheck(float(scales[mid]), math.inf if found is None else found[1])
                hi = mid - 1
            else:
                lo = mid + 1
        return best

    def _touches(self, poses: np.ndarray, pts: np.ndarray, start: np.ndarray, limit: float,
                 step: float) -> tuple[bool, float] | None:
        """Do ``poses`` (G, K + 1, 3) bring a point within ``limit`` of the footprint (and nearer
        than it started)? (touches, clearance beyond the margin), or None when no point is near."""
        # A point within d of the footprint lies within R + d of the centre, so within that plus
        # the travel between coarse poses of a coarse pose's centre.
        centres = poses[:, ::_COARSE_STRIDE, :2].reshape(-1, 2)
        r = self._radius + limit + step
        # Squared distances by one product: |p|^2 + |c|^2 - 2 p.c (p: the points, c: the centres).
        d2 = np.einsum("ij,ij->i", centres, centres)[:, None] - 2.0 * (centres @ pts.T)
        cand = np.nonzero(np.min(d2, axis=0) <= r * r - np.einsum("ij,ij->i", pts, pts))[0]
        if cand.size == 0:
            return None
        sub = pts[cand]
        flat = poses.reshape(-1, 3)
        c, s = np.cos(flat[:, 2]), np.sin(flat[:, 2])
        # Every point in every pose's body frame at once: one (2M, 2) @ (2, n) product.
        rot = np.empty((2 * len(flat), 2))
        rot[0::2, 0], rot[0::2, 1], rot[1::2, 0], rot[1::2, 1] = c, s, -s, c
        body = (rot @ sub.T).reshape(len(flat), 2, -1)
        off = rot.reshape(len(flat), 2, 2) @ flat[:, :2, None]  # (M, 2, 1): the pose's own position, turned
        qx = np.abs(body[:, 0] - off[:, 0]) - self._half[0]
        qy = np.abs(body[:, 1] - off[:, 1]) - self._half[1]
        near = np.maximum(qx, qy)  # <= the distance to the box, so near >= d rules a pair out
        if not self._box:
            near = np.hypot(body[:, 0] - off[:, 0], body[:, 1] - off[:, 1]) - self._radius
        low = float(near.min()) - limit + self.config.margin  # clearance beyond the margin, a lower bound
        maybe = near < limit
        if not maybe.any():
            return False, low
        # The exact distance only where the cheap bound could not decide.
        mq = np.nonzero(maybe)
        x, y = qx[mq], qy[mq]
        d = np.hypot(np.maximum(x, 0.0), np.maximum(y, 0.0)) + np.minimum(np.maximum(x, y), 0.0) if self._box else near[mq]
        touching = (d < limit) & (d < start[cand][mq[1]] - _TOL)
        return bool(touching.any()), low
