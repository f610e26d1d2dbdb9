"""A person (a 0.3 m box) and a kinematic base on a ``ComponentHarness``'s clock: what the
give-way tests feed the Behaviors each tick, and how near the two came."""
from __future__ import annotations

import math

import numpy as np

from emos import msgs as M
from emos.testing import ComponentHarness
from tests.nav.components.fake_base import base_messages

ROBOT_RADIUS, HALF = 0.2, 0.15  # the robot's radius, the person's half-width


def gap(robot: np.ndarray, person: np.ndarray) -> float:
    """Clearance (m) between the round robot at ``robot`` and the square person at ``person``."""
    dx = max(abs(robot[0] - person[0]) - HALF, 0.0)
    dy = max(abs(robot[1] - person[1]) - HALF, 0.0)
    return math.hypot(dx, dy) - ROBOT_RADIUS


def feed(h: ComponentHarness, pose: np.ndarray, v: float, w: float, person: np.ndarray) -> None:
    """Feed the odometry of the base at ``pose`` moving at (``v``, ``w``) and its 360-degree scan
    of the room and the person, stamped on the harness's clock (the mover tracker's)."""
    box = (person[0] - HALF, person[1] - HALF, person[0] + HALF, person[1] + HALF)
    odom, scan = base_messages(pose, v, w, 2 * math.pi, [box])
    odom.header.stamp = scan.header.stamp = M.Time.from_sec(h.time)
    h.feed("/odom", odom)
    h.feed("/scan", scan)
