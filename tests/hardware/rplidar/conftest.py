"""Emulated RPLIDARs on pseudo-terminals for the driver, component and cross-check tests."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.hardware.rplidar.emulator import RplidarEmulator

HOUSE = "actors/sim/data/kompass_sim/maps/turtlebot3_gazebo_house.yaml"


def smooth_world(pose, bearings):
    """A world whose range is a smooth, asymmetric function of the bearing (counter-clockwise):
    a clockwise/counter-clockwise mix-up or a shifted beam shows as a large error."""
    return 2.0 + 0.5 * np.sin(np.asarray(bearings)) + 0.25 * np.cos(2 * np.asarray(bearings))


def smooth_expected(angles: np.ndarray) -> np.ndarray:
    return smooth_world(None, angles)


SMOOTH_TOL = 0.5 * math.radians(0.5) * 1.6 + 0.001  # half a 1-deg beam of the slope, plus q2 rounding


@pytest.fixture
def emulator(tmp_path):
    made: list[RplidarEmulator] = []

    def make(source=smooth_world, pose=(0.0, 0.0, 0.0), **kw) -> RplidarEmulator:
        kw.setdefault("link", tmp_path / f"ttyRPLIDAR{len(made)}")
        emu = RplidarEmulator(source, pose, **kw).start()
        made.append(emu)
        return emu

    yield make
    for emu in made:
        emu.unplug()
