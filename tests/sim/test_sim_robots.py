import math

import numpy as np
import pytest

from emos.actors.sim import HOLONOMIC, JACKAL, RACECAR, TURTLEBOT3, Odometry, OdometryConfig, RobotSpec
from emos.actors.sim.robots import accelerate, feasible_command, integrate
from emos.geometry import wrap_angle

pytestmark = pytest.mark.sim


def test_commands_are_clipped_to_the_speed_limits(make_world):
    world = make_world(ground=False)
    robot = world.add_robot(TURTLEBOT3, (0.0, 0.0, 0.0))
    robot.command(5.0, 1.0, 10.0)
    world.step(200)  # 2 s: long enough to reach the limits
    vx, vy, w = robot.twist
    assert vx == pytest.approx(TURTLEBOT3.max_vx)
    assert vy == 0.0  # a differential drive cannot strafe
    assert w == pytest.approx(TURTLEBOT3.max_omega)


def test_acceleration_is_limited_per_tick(make_world):
    world = make_world(ground=False)
    robot = world.add_robot(TURTLEBOT3, (0.0, 0.0, 0.0))
    robot.command(0.22, 0.0, 0.0)
    speeds = []
    for _ in range(12):
        world.step()
        speeds.append(robot.twist[0])
    steps = np.diff([0.0] + speeds)
    assert np.all(steps <= TURTLEBOT3.max_acc_x * world.clock.dt + 1e-12)
    assert speeds[0] == pytest.approx(TURTLEBOT3.max_acc_x * world.clock.dt)
    assert speeds[-1] == pytest.approx(0.22)


def test_holonomic_base_strafes(make_world):
    world = make_world(ground=False)
    robot = world.add_robot(HOLONOMIC, (0.0, 0.0, math.pi / 2))
    robot.command(0.0, 0.5, 0.0)  # sideways to the left of a robot facing +y: towards -x
    world.step(300)
    assert robot.pose[0] < -1.2
    assert abs(robot.pose[1]) < 1e-6


def test_racecar_cannot_turn_on_the_spot_and_respects_its_steering_limit(make_world):
    world = make_world(ground=False)
    car = world.add_robot(RACECAR, (0.0, 0.0, 0.0))
    car.command(0.0, 0.0, 2.0)
    world.step(50)
    assert car.pose == pytest.approx([0.0, 0.0, 0.0])
    car.command(1.0, 0.0, 100.0)
    world.step(300)
    max_curvature = math.tan(RACECAR.max_steer) / RACECAR.wheelbase
    assert car.twist[2] == pytest.approx(car.twist[0] * max_curvature)


def test_constant_twist_integration_is_an_exact_circle():
    pose = np.array([0.0, 0.0, 0.0])
    for _ in range(100):
        pose = integrate(pose, np.array([1.0, 0.0, 1.0]), 2 * math.pi / 100)
    assert pose == pytest.approx([0.0, 0.0, 0.0], abs=1e-9)
    half = integrate(np.zeros(3), np.array([1.0, 0.0, 1.0]), math.pi)
    assert half[:2] == pytest.approx([0.0, 2.0], abs=1e-9)
    assert abs(wrap_angle(half[2] - math.pi)) < 1e-9  # facing back (pi and -pi are one heading)


def test_slip_makes_wheel_odometry_drift_from_ground_truth(make_world):
    world = make_world(ground=False)
    robot = world.add_robot(JACKAL, (0.0, 0.0, 0.0), slip=0.2)
    truth = world.add_sensor(Odometry(robot, OdometryConfig(rate_hz=100)))
    wheels = world.add_sensor(Odometry(robot, OdometryConfig(rate_hz=100, noisy=True, linear_noise=0.0, angular_noise=0.0),
                                       name="wheel_odom"))
    robot.command(1.0, 0.0, 0.0)
    world.step(300)
    # The body moved 20 % less than the wheels turned; encoders do not know that.
    assert truth.latest.x == pytest.approx(0.8 * wheels.latest.x, rel=0.02)
    assert truth.latest.x == pytest.approx(robot.pose[0])


def test_same_seed_same_trajectory_and_readings_with_noise(make_world):
    def run(seed):
        world = make_world(seed=seed, ground=False)
        world.add_wall((3.0, -5.0), (3.0, 5.0))
        robot = world.add_robot(JACKAL, (0.0, 0.0, 0.0), actuation_noise=0.1)
        odom = world.add_sensor(Odometry(robot, OdometryConfig(noisy=True)))
        trace = []
        for k in range(100):
            robot.command(0.5, 0.0, math.sin(k / 10))
            world.step()
            trace.append(np.r_[robot.pose, odom.latest.pose])
        return np.array(trace)

    a, b, c = run(7), run(7), run(8)
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 1e-3


def test_bad_commands_and_specs_are_rejected(make_world):
    world = make_world(ground=False)
    robot = world.add_robot("jackal")
    with pytest.raises(ValueError, match="finite"):
        robot.command(float("nan"))
    with pytest.raises(ValueError, match="unknown robot"):
        world.add_robot("r2d2")
    with pytest.raises(ValueError, match="omni robot needs max_vy"):
        RobotSpec("bad", "omni", 0.5, 0.5, 0.2, 1.0, 1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="max_vx"):
        RobotSpec("bad", "differential", 0.5, 0.5, 0.2, -1.0, 1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="slip"):
        world.add_robot("jackal", slip=1.5)


def test_feasible_command_and_acceleration_are_pure():
    cmd = feasible_command(JACKAL, 3.0, 1.0, -9.0)
    assert cmd.tolist() == [2.0, 0.0, -4.0]
    out = accelerate(JACKAL, np.zeros(3), cmd, 0.01)
    assert out == pytest.approx([0.2, 0.0, -0.25])


def test_reset_puts_the_robot_back_and_clears_its_history(make_world):
    world = make_world()
    world.add_wall((1.0, -2.0), (1.0, 2.0))
    robot = world.add_robot("jackal", (0.0, 0.0, 0.0))
    robot.command(1.0)
    world.step(200)
    assert robot.collided and robot.distance_travelled > 0.5
    robot.reset()
    assert robot.pose.tolist() == [0.0, 0.0, 0.0]
    assert not robot.collided and robot.distance_travelled == 0.0 and len(robot.trail) == 1
    world.step()
    assert robot.pose.tolist() == [0.0, 0.0, 0.0]  # the command was cleared too
