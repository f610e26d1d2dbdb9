"""emos.geometry: the one home of angle wrapping, yaw <-> quaternion and a message's planar pose."""
import math

import numpy as np
import pytest

from emos import msgs as M
from emos.geometry import planar_pose, quaternion_of_yaw, wrap_angle, yaw_of_quaternion

pytestmark = pytest.mark.unit


@pytest.mark.parametrize("angle, wrapped", [(0.0, 0.0), (math.pi, -math.pi), (-math.pi, -math.pi), (3 * math.pi / 2, -math.pi / 2),
                                            (-7.0, -7.0 + 2 * math.pi), (100.0, 100.0 - 32 * math.pi)])
def test_wrap_angle_gives_the_same_angle_in_minus_pi_to_pi(angle, wrapped):
    assert wrap_angle(angle) == pytest.approx(wrapped)
    assert isinstance(wrap_angle(angle), float)
    array = wrap_angle(np.array([angle, angle]))
    assert isinstance(array, np.ndarray) and np.allclose(array, wrapped)


def test_yaw_and_quaternion_round_trip_and_agree_with_the_message_type():
    for yaw in np.linspace(-math.pi, math.pi, 37, endpoint=False):
        q = quaternion_of_yaw(float(yaw))
        assert yaw_of_quaternion(*q) == pytest.approx(yaw)
        assert M.Quaternion.from_yaw(float(yaw)).yaw() == pytest.approx(yaw)
    # A tilted quaternion's heading: 90 deg about z, then pitched: still facing +y.
    half = math.sqrt(0.5)
    assert yaw_of_quaternion(0.0, 0.0, half, half) == pytest.approx(math.pi / 2)


def test_planar_pose_reads_every_pose_message_and_refuses_others():
    pose = M.Pose(position=M.Point(x=1.0, y=2.0), orientation=M.Quaternion.from_yaw(0.5))
    odom = M.Odometry()
    odom.pose.pose = pose
    stamped = M.PoseStamped(pose=pose)
    for msg in (pose, odom, stamped, M.PoseWithCovarianceStamped(pose=M.PoseWithCovariance(pose=pose))):
        assert planar_pose(msg) == pytest.approx((1.0, 2.0, 0.5)), type(msg).__name__
    assert planar_pose(M.Pose2D(x=3.0, y=4.0, theta=-1.0)) == (3.0, 4.0, -1.0)
    with pytest.raises(TypeError, match="expected a pose message .*got String"):
        planar_pose(M.String(data="x"))


@pytest.mark.parametrize("twist", [(0.5, 0.0, 0.0), (0.5, 0.2, 1.3), (0.0, 0.0, -2.0), (0.3, -0.1, 1e-8)])
def test_integrate_pose_is_exact_and_its_scalar_and_array_paths_agree(twist):
    from emos.geometry import integrate_pose

    start, dt = np.array([1.0, -2.0, 3.0]), 0.8
    exact = integrate_pose(start, np.array(twist), dt)
    # Fine Euler steps converge to the exact arc.
    pose = start.copy()
    n = 20000
    for _ in range(n):
        c, s = math.cos(pose[2]), math.sin(pose[2])
        pose = pose + np.array([twist[0] * c - twist[1] * s, twist[0] * s + twist[1] * c, twist[2]]) * (dt / n)
    assert exact[:2] == pytest.approx(pose[:2], abs=1e-4)
    assert exact[2] == pytest.approx(wrap_angle(float(pose[2])), abs=1e-9)
    batch = integrate_pose(np.stack([start, start]), np.array([twist, twist]), np.array([dt, dt]))
    assert batch.shape == (2, 3) and np.allclose(batch, exact, atol=1e-12)


def test_pose_history_interpolates_at_a_stamp_the_short_way_round_and_clamps_outside():
    from emos.geometry import PoseHistory

    history = PoseHistory(span=1.0)
    assert history.at(0.0) is None
    history.add(0.0, [0.0, 0.0, 3.0])
    history.add(0.5, [1.0, 2.0, -3.0])  # yaw crossed +-pi: 0.28 rad of turn, not 6
    history.add(0.5, [9.0, 9.0, 0.0])  # a repeated (or older) time is ignored
    np.testing.assert_allclose(history.at(0.25)[:2], [0.5, 1.0])
    assert abs(wrap_angle(history.at(0.25)[2] - math.pi)) < 1e-9
    np.testing.assert_allclose(history.at(-5.0), [0.0, 0.0, 3.0])  # before the oldest: the oldest
    np.testing.assert_allclose(history.at(7.0), [1.0, 2.0, -3.0])  # after the newest: the newest
    for k in range(1, 40):  # only the last ``span`` seconds are kept
        history.add(0.5 + 0.1 * k, [k, 0.0, 0.0])
    np.testing.assert_allclose(history.at(0.0), history.at(3.3 - 1.0 - 0.1))
    with pytest.raises(ValueError, match="span"):
        PoseHistory(span=0.0)
