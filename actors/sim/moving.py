"""Obstacles that move along scripted paths (people walking, carts, doors swinging past)."""
from __future__ import annotations

import math

import attrs
import numpy as np

from emos.config import validators as V

from .primitives import Box, Cylinder


def _waypoints(value: object) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 2 or len(arr) < 2 or not np.all(np.isfinite(arr)):
        raise ValueError(f"MovingObstacle.waypoints must be at least two finite (x, y) points, got {value!r}")
    if np.any(np.linalg.norm(np.diff(arr, axis=0), axis=1) == 0):
        raise ValueError("MovingObstacle.waypoints must not repeat a point consecutively")
    return arr


@attrs.define(eq=False)
class MovingObstacle:
    """A box or cylinder following ``waypoints`` at ``speed`` m/s.

    ``mode`` is ``"loop"`` (back to the first point after the last), ``"pingpong"`` (reverse
    at the ends) or ``"once"`` (stop at the last point). The shape's own ``center`` is ignored:
    its position is the path position at the current time.
    """

    shape: Box | Cylinder = attrs.field(validator=attrs.validators.instance_of((Box, Cylinder)))
    waypoints: np.ndarray = attrs.field(converter=_waypoints)
    speed: float = attrs.field(default=0.5, converter=float, validator=V.number(gt=0, finite=True, what="a finite speed in m/s"))
    mode: str = attrs.field(default="pingpong", validator=attrs.validators.in_(("loop", "pingpong", "once")))
    name: str = attrs.field(default="mover")

    def _path(self) -> np.ndarray:
        if self.mode == "loop":
            return np.vstack([self.waypoints, self.waypoints[:1]])
        return self.waypoints

    def pose_at(self, t: float) -> tuple[float, float, float]:
        """(x, y, heading) on the path at time ``t`` seconds."""
        path = self._path()
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        total = cum[-1]
        s = self.speed * max(t, 0.0)
        direction = 1.0
        if self.mode == "loop":
            s = s % total
        elif self.mode == "pingpong":
            s = s % (2 * total)
            if s > total:
                s, direction = 2 * total - s, -1.0
        else:
            s = min(s, total)
        k = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1))
        a, b = path[k], path[k + 1]
        p = a + (b - a) * ((s - cum[k]) / seg[k])
        d = (b - a) * direction
        return float(p[0]), float(p[1]), math.atan2(d[1], d[0])
