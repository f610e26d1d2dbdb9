"""Drive models: the calibrated skid-steer Jackal against the pybullet wheeled Jackal, and in a World."""
import math

import numpy as np
import pytest

from emos.actors.sim.dynamics import IdealDrive, SkidSteerDrive, SkidSteerParams, make_drive, twist_between
from emos.actors.sim.robots import HOLONOMIC, JACKAL, JACKAL_BARN, integrate

pytestmark = pytest.mark.sim


def _drive(model, commands, dt=0.01):
    """Body twists and the integrated pose of ``model`` driven by ``commands`` from rest."""
    model.reset(np.zeros(3))
    pose, twists, headings = np.zeros(3), [], []
    unwrapped = 0.0
    for cmd in commands:
        body, _ = model.step(np.asarray(cmd, float), dt)
        pose = integrate(pose, body, dt)
        unwrapped += body[2] * dt
        twists.append(body)
        headings.append(unwrapped)
    return np.array(twists), pose, np.array(headings)


def _responses(model):
    model.bind(JACKAL, np.random.default_rng(0))
    step, _, _ = _drive(model, [(2.0, 0, 0)] * 100)
    t90 = (int(np.argmax(step[:, 0] >= 1.8)) + 1) * 0.01
    _drive(model, [(2.0, 0, 0)] * 200)
    # Brake: from the speed reached, command zero.
    pose = np.zeros(3)
    for _ in range(200):
        body, _ = model.step(np.zeros(3), 0.01)
        pose = integrate(pose, body, 0.01)
    brake = math.hypot(pose[0], pose[1])
    turn, _, heading = _drive(model, [(1.0, 0, 2.0)] * 300)
    lateral, _, _ = _drive(model, [(2.0, 0, 4.0)] * 300)
    return {
        "t90": t90, "brake": brake,
        # Achieved / commanded yaw rate from 1 to 3 s (the wheeled model's yaw rate oscillates:
        # stick-slip of the scrubbing wheels; the heading averages it).
        "turn_ratio": (heading[299] - heading[99]) / (2.0 * 2.0), "turn_speed": turn[150:, 0].mean(),
        "heading": heading[[99, 199, 299]],
        "lateral": float(np.mean(lateral[150:, 0] * lateral[150:, 2])),
    }


@pytest.fixture(scope="module")
def wheeled():
    pytest.importorskip("pybullet")
    model = make_drive("wheeled")
    try:
        yield _responses(model)
    finally:
        model.close()


def test_wheeled_jackal_matches_the_reported_responses(wheeled):
    """The measured facts of the issue, with the fixed physics settings of wheeled.py."""
    assert wheeled["t90"] == pytest.approx(0.4, abs=0.1)  # 2 m/s step: 90 % in about 0.4 s
    assert wheeled["brake"] == pytest.approx(0.4, abs=0.05)  # braking from 2 m/s: about 0.4 m
    assert 0.4 <= wheeled["turn_ratio"] <= 1.1  # 1 m/s + 2 rad/s achieves 0.4-1.1 of the yaw rate
    assert wheeled["lateral"] == pytest.approx(3.8, abs=0.4)  # lateral acceleration saturates near 3.8


def test_skid_steer_model_matches_the_wheeled_jackal(wheeled):
    """Tolerances: step 90 % time +-0.08 s, braking distance +-0.05 m, turn speed +-0.08 m/s,
    lateral saturation +-0.3 m/s^2, heading in the turn +-0.25 rad at 1, 2 and 3 s (with the
    wheeled model's achieved gain), and the per-episode gain range covers that gain."""
    low, high = SkidSteerParams().yaw_gain_range
    assert low <= wheeled["turn_ratio"] <= high
    skid = _responses(SkidSteerDrive(yaw_gain=wheeled["turn_ratio"]))
    assert skid["t90"] == pytest.approx(wheeled["t90"], abs=0.08)
    assert skid["brake"] == pytest.approx(wheeled["brake"], abs=0.05)
    assert skid["turn_speed"] == pytest.approx(wheeled["turn_speed"], abs=0.08)
    assert skid["lateral"] == pytest.approx(wheeled["lateral"], abs=0.3)
    assert np.abs(skid["heading"] - wheeled["heading"]).max() < 0.25
    assert skid["turn_ratio"] == pytest.approx(wheeled["turn_ratio"], abs=0.03)


def test_ideal_drive_does_exactly_what_it_is_told():
    ideal = _responses(IdealDrive())
    assert ideal["t90"] == pytest.approx(0.09, abs=0.011)  # 20 m/s^2
    assert ideal["turn_ratio"] == pytest.approx(1.0)
    assert ideal["brake"] < 0.15


def test_yaw_gain_is_drawn_per_episode_from_the_range_and_reproducible():
    gains = []
    for seed in range(20):
        drive = SkidSteerDrive()
        drive.bind(JACKAL, np.random.default_rng(seed))
        gains.append(drive.yaw_gain)
    assert all(0.6 <= g <= 1.0 for g in gains)
    assert len(set(np.round(gains, 6))) == 20
    again = SkidSteerDrive()
    again.bind(JACKAL, np.random.default_rng(3))
    assert again.yaw_gain == gains[3]
    assert "yaw_gain" in again.describe()


def test_bad_parameters_are_refused_by_name():
    with pytest.raises(ValueError, match="yaw_gain_range"):
        SkidSteerParams(yaw_gain_range=(1.0, 0.5))
    with pytest.raises(ValueError, match="SkidSteerParams.lag"):
        SkidSteerParams(lag=0.0)
    with pytest.raises(ValueError, match="unknown drive model 'tank'"):
        make_drive("tank")
    with pytest.raises(ValueError, match="differential"):
        SkidSteerDrive().bind(HOLONOMIC, np.random.default_rng(0))


def test_twist_between_inverts_integrate():
    rng = np.random.default_rng(1)
    for _ in range(50):
        pose = rng.uniform(-3, 3, 3)
        twist = rng.uniform(-2, 2, 3)
        after = integrate(pose, twist, 0.05)
        assert twist_between(pose, after, 0.05) == pytest.approx(twist, abs=1e-9)


# -- in a World ------------------------------------------------------------------------------

def test_jackal_barn_robot_slips_in_turns_and_its_wheels_over_report(make_world):
    world = make_world(ground=False)
    robot = world.add_robot("jackal-barn", (0.0, 0.0, 0.0))
    assert isinstance(robot.drive, SkidSteerDrive)
    gain = robot.drive.yaw_gain
    for _ in range(300):  # a command every tick: the watchdog never fires
        robot.command(1.0, 0.0, 1.0)
        world.step()
    assert robot.twist[2] == pytest.approx(gain * 1.0, rel=0.02)
    assert robot.wheel_twist[2] == pytest.approx(1.0, rel=0.01)  # encoders see the commanded turn


def test_the_base_stops_when_commands_stop_for_a_quarter_second(make_world):
    world = make_world(ground=False)
    robot = world.add_robot("jackal-barn", (0.0, 0.0, 0.0))
    for _ in range(100):
        robot.command(1.0, 0.0, 0.0)
        world.step()
    assert robot.twist[0] == pytest.approx(1.0, abs=0.02)
    world.step(24)  # 0.24 s without a command: still driving
    assert robot.twist[0] > 0.9
    world.step(60)  # past 0.25 s: the watchdog stopped it (braking at ~4.9 m/s^2)
    assert robot.twist[0] == pytest.approx(0.0, abs=1e-6)
    ideal = world.add_robot("jackal", (0.0, 5.0, 0.0))
    ideal.command(1.0, 0.0, 0.0)
    world.step(200)
    assert ideal.twist[0] == pytest.approx(1.0)  # the ideal base has no watchdog (unchanged behaviour)


def test_slip_parameters_belong_to_the_ideal_drive(make_world):
    world = make_world(ground=False)
    with pytest.raises(ValueError, match="ideal drive"):
        world.add_robot("jackal-barn", (0.0, 0.0, 0.0), slip=0.1)
    robot = world.add_robot("jackal", (0.0, 0.0, 0.0), drive="skid-steer")
    assert robot.drive.name == "skid-steer"


def test_wheeled_jackal_drives_in_a_world_and_stops_at_an_obstacle(make_world):
    world = make_world()
    world.add_cylinder((2.0, 0.0), 0.2)
    robot = world.add_robot("jackal-wheeled", (0.0, 0.0, 0.0))
    assert robot.drive.name == "wheeled"
    for _ in range(300):
        robot.command(1.0, 0.0, 0.0)
        world.step()
        if robot.collided:
            break
    assert robot.collided
    # Touched where the front wheels / chassis meet the cylinder: 2.0 - 0.2 - 0.229 m.
    assert robot.pose[0] == pytest.approx(2.0 - 0.2 - 0.229, abs=0.06)
    assert abs(robot.pose[1]) < 0.05
    # The wheeled simulation restarts at rest where the World put the robot back: backing off works.
    touched_at = robot.pose[0]
    for _ in range(100):
        robot.command(-0.5, 0.0, 0.0)
        world.step()
    assert touched_at - robot.pose[0] > 0.25
    assert not robot.contacts


def test_official_collision_shape_is_the_chassis_and_the_wheels(make_world):
    """A post just beyond a front wheel but inside the old bounding box does not touch the
    official shape; one touching a wheel does."""
    touched = {}
    for name in ("jackal-barn", "jackal"):
        world = make_world()
        world.add_cylinder((0.245, 0.19), 0.01)  # x beyond the wheel (0.229), inside the 0.508 m box
        robot = world.add_robot(name, (0.0, 0.0, 0.0))
        world.step()
        touched[name] = robot.collided
    assert touched == {"jackal-barn": False, "jackal": True}
    assert JACKAL_BARN.length == pytest.approx(0.458) and JACKAL_BARN.width == pytest.approx(0.4156)
    world2 = make_world()
    world2.add_cylinder((0.13, 0.23), 0.03)  # beside the front-left wheel (y 0.1678..0.2078)
    robot = world2.add_robot("jackal-barn", (0.0, 0.0, 0.0))
    world2.step()
    assert robot.collided
