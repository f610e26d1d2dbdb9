import math

import numpy as np
import pytest

from emos.actors.nav.kinematics import (
    dynamic_window,
    feasible_commands,
    integrate,
    limit_command_change,
    rollout,
    to_robot_frame,
    to_world_frame,
    wrap_angle,
)
from emos.actors.nav.robot import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotType

pytestmark = pytest.mark.unit


def robot(model, **kw):
    return RobotConfig(
        model_type=model, geometry_type="CYLINDER", geometry_params=[0.2, 0.3],
        ctrl_vx_limits=LinearCtrlLimits(1.0, 1.0, 2.0),
        ctrl_vy_limits=LinearCtrlLimits(0.5, 0.5, 1.0),
        ctrl_omega_limits=AngularCtrlLimits(1.0, 2.0, 4.0, math.pi / 4), **kw)


def test_rollout_straight_and_circle_closed_form():
    cmds = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 0.5, 0.0]])
    poses = rollout([0.0, 0.0, 0.0], cmds, dt=0.1, steps=int(round(2 * math.pi / 0.1)))
    assert poses.shape == (3, 64, 3)
    np.testing.assert_allclose(poses[0, 10], [1.0, 0.0, 0.0], atol=1e-12)
    # unit-speed circle of radius 1 centred at (0, 1): every pose on the circle
    r = np.hypot(poses[1, :, 0], poses[1, :, 1] - 1.0)
    np.testing.assert_allclose(r, 1.0, atol=1e-9)
    np.testing.assert_allclose(poses[2, 10], [0.0, 0.5, 0.0], atol=1e-12)


def test_integrate_matches_fine_euler():
    cmd = np.array([0.7, 0.2, -0.9])
    pose = np.array([1.0, -2.0, 0.4])
    exact = integrate(pose, cmd, 1.5)
    p = pose.copy()
    h = 1e-5
    for _ in range(int(1.5 / h)):
        c, s = math.cos(p[2]), math.sin(p[2])
        p = p + h * np.array([c * cmd[0] - s * cmd[1], s * cmd[0] + c * cmd[1], cmd[2]])
    np.testing.assert_allclose(exact[:2], p[:2], atol=1e-4)
    assert abs(wrap_angle(exact[2] - p[2])) < 1e-4


def test_feasible_commands_per_model():
    cmd = np.array([[2.0, 1.0, 3.0], [0.0, 0.0, 1.0]])
    diff = feasible_commands(robot(RobotType.DIFFERENTIAL_DRIVE), cmd)
    np.testing.assert_allclose(diff, [[1.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    omni = feasible_commands(robot(RobotType.OMNI), cmd)
    np.testing.assert_allclose(omni, [[1.0, 0.5, 1.0], [0.0, 0.0, 1.0]])
    ack_robot = robot(RobotType.ACKERMANN, wheel_base=0.5)
    ack = feasible_commands(ack_robot, np.array([[0.2, 0.0, 1.0], [0.0, 0.0, 1.0]]))
    # |omega| <= |v| tan(pi/4) / 0.5 = 0.4; and no spinning in place
    np.testing.assert_allclose(ack, [[0.2, 0.0, 0.4], [0.0, 0.0, 0.0]])


def test_dynamic_window_uses_acc_and_decel_separately():
    r = robot(RobotType.OMNI)
    win = dynamic_window(r, [0.5, 0.0, 0.0], 0.1)
    np.testing.assert_allclose(win[0], [0.5 - 0.2, 0.5 + 0.1])
    np.testing.assert_allclose(win[1], [-0.05, 0.05])
    np.testing.assert_allclose(win[2], [-0.2, 0.2])
    # braking through zero: 0.1 m/s at 2 m/s^2 stops after 0.05 s, then 0.05 s backwards at 1
    win = dynamic_window(r, [0.1, 0.0, 0.0], 0.1)
    np.testing.assert_allclose(win[0], [-0.05, 0.2])
    assert np.all(dynamic_window(robot(RobotType.DIFFERENTIAL_DRIVE), [0.1, 0, 0], 0.1)[1] == 0)
    with pytest.raises(ValueError, match="dt"):
        dynamic_window(r, [0, 0, 0], 0.0)


def test_limit_command_change_braking_faster_than_speeding_up():
    r = robot(RobotType.DIFFERENTIAL_DRIVE)
    up = limit_command_change(r, [0.0, 0, 0], [1.0, 0, 0], 0.1)
    down = limit_command_change(r, [1.0, 0, 0], [0.0, 0, 0], 0.1)
    assert up[0] == pytest.approx(0.1)
    assert down[0] == pytest.approx(0.8)


def test_frame_round_trip():
    pose = np.array([1.0, 2.0, 0.7])
    pts = np.random.default_rng(0).normal(size=(20, 2))
    np.testing.assert_allclose(to_world_frame(pose, to_robot_frame(pose, pts)), pts, atol=1e-12)


def test_a_command_sequence_integrates_in_one_pass_to_the_poses_of_step_by_step_arcs():
    """``integrate_sequence`` sums all steps at once; every pose must be the one the step-by-step
    exact arcs (``integrate_pose``, heading wrapped each step) reach, straight steps included."""
    from emos.actors.nav.kinematics import integrate_sequence
    from emos.geometry import integrate_pose, wrap_angle

    rng = np.random.default_rng(3)
    cmds = np.c_[rng.uniform(-0.5, 1.5, 40 * 25), rng.uniform(-0.4, 0.4, 40 * 25), rng.uniform(-3.0, 3.0, 40 * 25)].reshape(40, 25, 3)
    cmds[:5, :, 2] = 0.0  # straight
    cmds[5:10, :, 2] = 1e-8  # the small-turn branch
    start = np.array([0.7, -1.2, 3.0])  # near +pi: the heading wraps along the way
    got = integrate_sequence(start, cmds, 0.1)
    want = np.empty_like(got)
    want[:, 0] = start
    for k in range(cmds.shape[1]):
        want[:, k + 1] = integrate_pose(want[:, k], cmds[:, k], 0.1)
    np.testing.assert_allclose(got[..., :2], want[..., :2], rtol=0, atol=1e-9)
    np.testing.assert_allclose(wrap_angle(got[..., 2] - want[..., 2]), 0.0, atol=1e-9)
    assert (np.abs(got[..., 2]) <= np.pi).all()
