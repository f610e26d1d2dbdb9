"""Progress checking for the Controller: is the robot getting closer to the end of its plan?

A robot can be stuck without any single step failing: the local planner keeps finding arcs,
but they wiggle in front of a gap the robot does not fit, or it stands still because nothing
clear leads anywhere. Nav2's controller server has a progress checker for this; ours measures
progress as the length of plan still ahead (which shrinks as the robot advances, and is the
new plan's length after a re-plan, so it plays the role of the cost-to-go). No drop of
``distance`` m within ``timeout`` s of the clock (simulated time under a simulator) is a stall;
the Controller reports it as an ALGORITHM failure, which a recipe's fallbacks act on
(``controller.on_algorithm_fail(...)``: back out with the DriveManager, block the plan's
tightest spot with the Planner; see docs/navigation.md).
"""
from __future__ import annotations

import math

__all__ = ["ProgressChecker"]


class ProgressChecker:
    """``update(now, remaining)`` -> True once per stall (then it starts counting again)."""

    def __init__(self, timeout: float, distance: float) -> None:
        if not (timeout > 0 and distance > 0):
            raise ValueError(f"ProgressChecker: timeout and distance must be > 0, got {timeout!r}, {distance!r}")
        self.timeout, self.distance = float(timeout), float(distance)
        self._ref: tuple[float, float] | None = None  # (since, remaining to beat)

    def reset(self) -> None:
        self._ref = None

    def update(self, now: float, remaining: float) -> bool:
        if not math.isfinite(remaining):
            return False
        if self._ref is None or remaining < self._ref[1] - self.distance or now < self._ref[0]:
            self._ref = (now, remaining)  # progress (or a clock that went back: a new run)
            return False
        if now - self._ref[0] >= self.timeout:
            self._ref = (now, remaining)
            return True
        return False

    def describe(self) -> str:
        return f"less than {self.distance:g} m of progress along the plan in {self.timeout:g} s"
