"""Recovery behavior planners (actors/nav/recovery.py): each moves or refuses with a reason."""
import math

import numpy as np
import pytest

from emos.actors.nav import RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.recovery import plan_back_up, plan_drive_on_heading, plan_spin, plan_wait, rear_covered

pytestmark = pytest.mark.unit


def _round() -> RobotConfig:
    return RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                       geometry_params=np.array([0.2, 0.3]))


def _long() -> RobotConfig:  # 0.8 x 0.4 m box: its corners swing out to 0.45 m when it turns
    return RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.BOX,
                       geometry_params=np.array([0.8, 0.4, 0.3]))


def test_back_up_refuses_with_an_obstacle_behind_and_names_the_gap():
    wall_behind = np.array([[-0.32, y] for y in np.linspace(-0.3, 0.3, 13)])  # 0.12 m behind a 0.2 m radius
    plan = plan_back_up(_round(), wall_behind, 0.3)
    assert not plan.feasible and plan.commands.shape == (0, 3)
    assert plan.reason.startswith("back_up refused: obstacle 0.12 m behind"), plan.reason


def test_back_up_drives_back_when_the_rear_is_clear():
    ahead = np.array([[0.4, 0.0]])  # close in front: irrelevant when backing
    plan = plan_back_up(_round(), ahead, 0.3, speed=0.1, dt=0.1)
    assert plan.feasible, plan.reason
    assert np.all(plan.commands[:, 0] < 0) and math.isclose(-plan.commands[:, 0].sum() * plan.dt, 0.3, rel_tol=1e-6)


def test_back_up_refuses_blind():
    plan = plan_back_up(_round(), np.zeros((0, 2)), 0.3, rear_seen=False)
    assert not plan.feasible and "nothing sees behind" in plan.reason


def test_rear_covered_by_scan_field_of_view():
    assert not rear_covered(-math.radians(135), math.radians(135))  # a 270 deg scanner
    assert rear_covered(-math.pi, math.pi - 0.01)
    assert rear_covered(0.0, 2 * math.pi)


def test_spin_refuses_when_a_corner_would_touch():
    post = np.array([[0.0, 0.35]])  # beside the long robot: clear now (0.15 m), hit by a corner when it turns
    plan = plan_spin(_long(), post, math.pi / 2)
    assert not plan.feasible
    assert plan.reason.startswith("spin refused: the footprint would come within"), plan.reason


def test_spin_turns_when_clear_and_by_the_angle_asked():
    plan = plan_spin(_round(), np.array([[0.0, 0.35]]), -math.pi, max_omega=0.5, dt=0.1)
    assert plan.feasible
    assert math.isclose(plan.commands[:, 2].sum() * plan.dt, -math.pi, rel_tol=1e-6)
    assert np.all(np.abs(plan.commands[:, 2]) <= 0.5 + 1e-9)


def test_drive_on_heading_refuses_with_an_obstacle_ahead():
    plan = plan_drive_on_heading(_round(), np.array([[0.5, 0.0]]), 1.0)
    assert not plan.feasible and "obstacle 0.30 m ahead" in plan.reason


def test_wait_and_bad_numbers():
    assert plan_wait(1.0, dt=0.1).commands.shape == (10, 3)
    with pytest.raises(ValueError, match="back_up: distance"):
        plan_back_up(_round(), None, float("nan"))
    with pytest.raises(ValueError, match="wait: duration"):
        plan_wait(-1.0)
