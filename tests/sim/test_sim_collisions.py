import numpy as np
import pytest

from emos.actors.sim import Box, ContactSensor, MovingObstacle

pytestmark = pytest.mark.sim


def test_driving_into_a_wall_is_detected_and_stops_the_robot(make_world):
    world = make_world()
    world.add_wall((2.0, -3.0), (2.0, 3.0), thickness=0.2)  # face at x = 1.9
    robot = world.add_robot("jackal", (0.0, 0.0, 0.0))
    contacts = world.add_sensor(ContactSensor(robot, rate_hz=10))
    robot.command(1.0, 0.0, 0.0)
    world.step(300)
    assert robot.collided
    front = robot.pose[0] + robot.spec.length / 2
    assert front == pytest.approx(1.9, abs=0.03)  # stopped where it touched, not inside
    assert front < 1.9 + 1e-3
    assert contacts.latest.in_collision
    assert all(c.other == "static" for c in contacts.latest.contacts)
    assert all(c.position[0] == pytest.approx(1.9, abs=0.01) for c in contacts.latest.contacts)


def test_no_false_collision_when_passing_close(make_world):
    world = make_world()
    world.add_wall((-5.0, 0.3), (5.0, 0.3), thickness=0.1)  # face at y = 0.25, robot half-width 0.215
    robot = world.add_robot("jackal", (-4.0, 0.0, 0.0))
    robot.command(1.0, 0.0, 0.0)
    world.step(500)
    assert robot.pose[0] > 0.5
    assert not robot.collided


def test_a_moving_obstacle_hits_a_standing_robot(make_world):
    world = make_world()
    mover = MovingObstacle(Box((0, 0), (0.4, 0.4)), waypoints=[(-3.0, 0.0), (3.0, 0.0)], speed=1.0, name="cart")
    world.add(mover)
    robot = world.add_robot("jackal", (1.0, 0.0, 0.0))
    contacts = world.add_sensor(ContactSensor(robot, rate_hz=100))
    seen = []
    contacts.subscribe(lambda r: seen.extend(r.contacts))
    world.step(400)
    assert robot.collided
    assert {c.other for c in seen} == {"cart"}
    # First contact when the cart's front (x + 0.2) reaches the robot's back (1.0 - 0.254).
    first = min(c.stamp for c in seen)
    assert first == pytest.approx((1.0 - 0.254 - 0.2 + 3.0) / 1.0, abs=0.03)


def test_moving_obstacle_paths():
    box = Box((0, 0), (0.2, 0.2))
    ping = MovingObstacle(box, [(0, 0), (2, 0)], speed=1.0, mode="pingpong")
    assert ping.pose_at(1.0)[:2] == pytest.approx((1.0, 0.0))
    assert ping.pose_at(3.0)[:2] == pytest.approx((1.0, 0.0))
    assert np.cos(ping.pose_at(3.0)[2]) == pytest.approx(-1.0)  # heading back
    loop = MovingObstacle(box, [(0, 0), (1, 0), (1, 1)], speed=1.0, mode="loop")
    assert loop.pose_at(2.0 + 2 ** 0.5)[:2] == pytest.approx((0.0, 0.0), abs=1e-9)
    once = MovingObstacle(box, [(0, 0), (1, 0)], speed=1.0, mode="once")
    assert once.pose_at(10.0)[:2] == pytest.approx((1.0, 0.0))
    with pytest.raises(ValueError, match="waypoints"):
        MovingObstacle(box, [(0, 0)])
    with pytest.raises(ValueError, match="speed"):
        MovingObstacle(box, [(0, 0), (1, 0)], speed=0)
