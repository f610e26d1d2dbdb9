"""Stuck detection and recovery, pure: time and the distance still to go in, decisions out.

A robot can be stuck without any single step failing: the local planner keeps finding arcs,
but they wiggle in front of a gap the robot does not fit, or it stands still because nothing
clear leads anywhere. Both navigation stacks share the pieces here, and neither reads a clock
of its own (they pass the simulated time under a simulator), so they are tested on made-up time:

- :class:`ProgressChecker` (both): fed ``(now, remaining)`` where ``remaining`` is how far the
  robot still has to go (the cost-to-go at its pose, or the length of plan still ahead, which
  is the new plan's length after a re-plan), it says "stuck" once per ``timeout`` s in which
  ``remaining`` did not drop by ``distance`` m. Nav2's controller server has such a progress
  checker.
- :class:`BackOutThenBlock` (the in-process navigator, ``navigator/mapless.py``): on a stall,
  back out for ``recovery_time`` s; stalled again soon after, the route itself is impossible,
  so also block its tightest spot.
- :class:`StallHold` (the Controller component): a reported stall holds until the robot has
  moved, so a fallback sees it and a recovery clears it. The component stack's recovery
  itself is the recipe's fallback ladder (``DriveManager.move_backward``, then
  ``Planner.block_tightest_spot``; docs/navigation.md "Stuck recovery").
"""
from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # annotations only: this module stays free of numpy at run time
    import numpy as np

__all__ = ["BackOutThenBlock", "ProgressChecker", "Recovery", "StallHold"]


class ProgressChecker:
    """``update(now, remaining)`` -> True once per stall (then it starts counting again)."""

    def __init__(self, timeout: float, distance: float) -> None:
        if not (timeout > 0 and distance > 0):
            raise ValueError(f"ProgressChecker: timeout and distance must be > 0, got {timeout!r}, {distance!r}")
        self.timeout, self.distance = float(timeout), float(distance)
        self._ref: tuple[float, float] | None = None  # (since, remaining to beat)

    def reset(self) -> None:
        """Forget the reference: counting starts again at the next update (a new plan or goal,
        waiting for a moving obstacle, a switched algorithm)."""
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


class Recovery(enum.Enum):
    """What :meth:`BackOutThenBlock.on_stall` asks of the navigator."""

    BACK_OUT = "back_out"  # back out (prefer reversing) for ``recovery_time``
    BLOCK_AND_BACK_OUT = "block_and_back_out"  # block the route's tightest spot, re-plan, and back out


class BackOutThenBlock:
    """The in-process navigator's recovery. A first stall: back out for ``recovery_time`` s
    (pockets, a nose against a wall). A stall within ``escalate_within`` s of the previous
    one (by default ``3 * stuck_time + recovery_time``): the route is impossible, so block
    its tightest spot as well. ``backing_out(now)`` is True while a back-out is in force."""

    def __init__(self, stuck_time: float, recovery_time: float, escalate_within: float | None = None) -> None:
        if not (stuck_time > 0 and recovery_time >= 0):
            raise ValueError(f"BackOutThenBlock: stuck_time must be > 0 and recovery_time >= 0, got {stuck_time!r}, {recovery_time!r}")
        self.recovery_time = float(recovery_time)
        self.escalate_within = 3 * stuck_time + recovery_time if escalate_within is None else float(escalate_within)
        self.reset()

    def reset(self) -> None:
        self._last_stall = -math.inf
        self._until = -math.inf

    def on_stall(self, now: float) -> Recovery:
        escalate = now - self._last_stall < self.escalate_within
        self._last_stall = now
        self._until = now + self.recovery_time
        return Recovery.BLOCK_AND_BACK_OUT if escalate else Recovery.BACK_OUT

    def backing_out(self, now: float) -> bool:
        return now < self._until


class StallHold:
    """A stall reported at a position holds until the robot is ``release`` m away from it."""

    def __init__(self, release: float = 0.1) -> None:
        self.release = float(release)
        self.at: tuple[float, float] | None = None

    def hold(self, xy: Sequence[float] | np.ndarray) -> None:
        self.at = (float(xy[0]), float(xy[1]))

    def holding(self, xy: Sequence[float] | np.ndarray) -> bool:
        """True while the robot is still near the stall; once it has moved away, released."""
        if self.at is not None and math.dist((float(xy[0]), float(xy[1])), self.at) < self.release:
            return True
        self.at = None
        return False

    def clear(self) -> None:
        self.at = None
