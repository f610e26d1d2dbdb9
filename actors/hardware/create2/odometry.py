"""Differential-drive odometry from the Create 2's wrapping 16-bit encoder counts (pure)."""
from __future__ import annotations

import math

from emos.geometry import wrap_angle

from . import protocol as P


class DiffDriveOdometry:
    """Integrates (left, right) encoder readings into a pose (x, y, theta) and velocities.

    The first reading only sets the reference (the counters start anywhere). Each later one
    adds ``protocol.encoder_delta`` counts per wheel, so a roll-over at 16 bits is a small step
    and the pose never jumps. Midpoint integration: exact for a constant-curvature step.
    """

    def __init__(self, pose: tuple[float, float, float] = (0.0, 0.0, 0.0), *, m_per_count: float = P.M_PER_COUNT,
                 wheel_base: float = P.WHEEL_BASE_M) -> None:
        self.x, self.y, self.th = pose
        self.m_per_count = m_per_count
        self.wheel_base = wheel_base
        self.v = self.w = 0.0
        self._last: tuple[int, int] | None = None

    def reset_reference(self) -> None:
        """Forget the last reading (after a reconnect the robot may have been power-cycled)."""
        self._last = None

    def update(self, left: int, right: int, dt: float) -> None:
        if self._last is None:
            self._last = (left, right)
            return
        dl = P.encoder_delta(left, self._last[0]) * self.m_per_count
        dr = P.encoder_delta(right, self._last[1]) * self.m_per_count
        self._last = (left, right)
        ds, dth = (dr + dl) / 2.0, (dr - dl) / self.wheel_base
        mid = self.th + dth / 2.0
        self.x += ds * math.cos(mid)
        self.y += ds * math.sin(mid)
        self.th = float(wrap_angle(self.th + dth))
        if dt > 0:
            self.v, self.w = ds / dt, dth / dt
