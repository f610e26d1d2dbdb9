"""What a planning query returns."""
from __future__ import annotations

import attrs
import numpy as np

__all__ = ["PlanResult"]


@attrs.define(frozen=True)
class PlanResult:
    """Outcome of one global planning query.

    ``path`` is (N, 3) [x, y, yaw] in the map's world frame, interpolated to the configured
    resolution and verified collision-free by fcl; it is empty when ``solved`` is False.
    ``status`` is OMPL's planner status name (``EXACT_SOLUTION``, ``TIMEOUT``,
    ``INVALID_START``, ...) or ``PATH_IN_COLLISION`` if final verification failed.
    """

    solved: bool
    path: np.ndarray
    planner: str
    status: str
    planning_time_s: float
    simplification_time_s: float
    length_m: float
    message: str = ""

    @property
    def n_points(self) -> int:
        return int(len(self.path))
