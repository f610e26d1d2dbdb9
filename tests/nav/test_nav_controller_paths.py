"""Closed-loop path following: every path follower, every motion model, three path shapes,
with and without an obstacle on the path (tests/nav/sim2d.py simulates the robot and scan)."""
import numpy as np
import pytest

from emos.actors.nav.controllers import DVZ, DWA, PurePursuit, PurePursuitConfig, Stanley
from emos.actors.nav.controllers.base import ControlStatus

from .sim2d import World, circle_path, make_robot, run_closed_loop, straight_path, u_turn_path

pytestmark = pytest.mark.unit

MODELS = ["DIFFERENTIAL_DRIVE", "OMNI", "ACKERMANN"]
PATHS = {
    "straight": (straight_path, (2.0, 0.0, 0.15)),
    "u_turn": (u_turn_path, (3.0, 1.0, 0.15)),
    "circle": (circle_path, (1.5, 1.5, 0.15)),
}


def pure_pursuit(robot):
    # A car cannot turn in place: it needs to see an obstacle from farther away.
    horizon = 20 if robot.model_type.name == "ACKERMANN" else 10
    return PurePursuit(robot, PurePursuitConfig(prediction_horizon=horizon))


FACTORIES = {"PurePursuit": pure_pursuit, "DWA": DWA, "DVZ": DVZ, "Stanley": Stanley}
AVOIDING = ["PurePursuit", "DWA", "DVZ"]  # Stanley is sensor-less by design (see spec)


def _run(name, model, path_name, with_obstacle, budget=800):
    robot = make_robot(model)
    controller = FACTORIES[name](robot)
    make_path, obstacle = PATHS[path_name]
    path = make_path()
    controller.set_path(path)
    world = World([obstacle] if with_obstacle else [])
    result = run_closed_loop(controller, robot, world, (0.0, 0.0, 0.0), max_steps=budget)
    return robot, path, result


@pytest.mark.parametrize("path_name", list(PATHS))
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("name", list(FACTORIES))
def test_reaches_end_of_free_path(name, model, path_name):
    robot, path, res = _run(name, model, path_name, with_obstacle=False)
    assert res.reached, f"{name}/{model}/{path_name}: not at goal after {res.steps} steps, at {res.poses[-1]}"
    assert np.hypot(*(res.poses[-1][:2] - path[-1])) <= 0.1 + 1e-9
    # It followed the path, not a shortcut: every pose stays close to the reference.
    from emos.actors.nav.costs import polyline_distance_exact
    assert polyline_distance_exact(res.poses[:, :2], path).max() < 0.35


@pytest.mark.parametrize("path_name", list(PATHS))
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("name", AVOIDING)
def test_reaches_end_around_obstacle_on_path(name, model, path_name):
    robot, path, res = _run(name, model, path_name, with_obstacle=True)
    assert res.reached, f"{name}/{model}/{path_name}: stuck after {res.steps} steps at {res.poses[-1]}"
    # Clearance is footprint-to-obstacle distance: never touching.
    assert res.min_clearance > 0.0


def test_no_path_means_stop():
    robot = make_robot("DIFFERENTIAL_DRIVE")
    for factory in FACTORIES.values():
        res = factory(robot).compute(np.zeros(3), np.zeros(3))
        assert res.status is ControlStatus.NO_PATH
        assert np.all(res.command == 0)


@pytest.mark.parametrize("name", AVOIDING)
def test_wall_across_the_path_blocks_without_collision(name):
    robot = make_robot("DIFFERENTIAL_DRIVE")
    controller = FACTORIES[name](robot)
    controller.set_path(straight_path())
    wall = World([(2.0, y, 0.12) for y in np.linspace(-2.0, 2.0, 17)])
    res = run_closed_loop(controller, robot, wall, (0.0, 0.0, 0.0), max_steps=150)
    assert not res.reached
    assert res.min_clearance > 0.0


@pytest.mark.parametrize("path_name", ["straight", "u_turn"])
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("name", AVOIDING)
def test_box_footprint_passes_obstacle_without_touching(name, model, path_name):
    """A rectangular robot: clearance is measured from its rotated box, not a circle."""
    robot = make_robot(model, "BOX", (0.4, 0.3, 0.2))
    controller = FACTORIES[name](robot)
    make_path, obstacle = PATHS[path_name]
    controller.set_path(make_path())
    res = run_closed_loop(controller, robot, World([obstacle]), (0.0, 0.0, 0.0), max_steps=800)
    assert res.reached, f"{name}/{model}/{path_name}: stuck at {res.poses[-1]}"
    assert res.min_clearance > 0.0


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("name", AVOIDING)
def test_slalom_through_three_obstacles(name, model):
    robot = make_robot(model)
    controller = FACTORIES[name](robot)
    controller.set_path(straight_path(6.0))
    world = World([(1.5, 0.1, 0.15), (3.0, -0.15, 0.2), (4.5, 0.0, 0.15)])
    res = run_closed_loop(controller, robot, world, (0.0, 0.0, 0.0), max_steps=900)
    assert res.reached, f"{name}/{model}: stuck at {res.poses[-1]}"
    assert res.min_clearance > 0.0


@pytest.mark.parametrize("model", MODELS)
def test_sensorless_stanley_behind_drive_safety_stops_before_the_obstacle(model):
    """The spec pairs Stanley (no obstacle handling) with the DriveManager's safety zones."""
    from emos.actors.nav.controllers.clearance import pose_clearance
    from emos.actors.nav.kinematics import integrate
    from emos.actors.nav.safety import DriveSafety, SafetyZonesConfig

    robot = make_robot(model)
    stanley = Stanley(robot)
    stanley.set_path(straight_path())
    drive = DriveSafety(robot, SafetyZonesConfig(critical_zone_distance=0.1, slowdown_zone_distance=0.3))
    world = World([(2.0, 0.0, 0.15)])
    boundary = world.boundary_points()
    pose, vel = np.zeros(3), np.zeros(3)
    for _ in range(300):
        scan = world.scan(pose)
        cmd, check = drive.step(stanley.compute(pose, vel, scan).command, scan)
        vel = cmd
        pose = integrate(pose, vel, 0.1)
        assert pose_clearance(robot, pose[None], boundary)[0] > 0.0
    # The slowdown zone brings it to a halt at the edge of the critical zone (0.1 m).
    assert abs(vel[0]) < 0.02
    assert pose_clearance(robot, pose[None], boundary)[0] == pytest.approx(0.1, abs=0.03)


@pytest.mark.parametrize("geometry,params", [
    ("ELLIPSOID", (0.25, 0.15, 0.2)), ("SPHERE", (0.2,)), ("CAPSULE", (0.15, 0.3)), ("CONE", (0.15, 0.3)),
])
@pytest.mark.parametrize("name", ["PurePursuit", "DWA"])
def test_every_geometry_type_passes_an_obstacle(name, geometry, params):
    robot = make_robot("DIFFERENTIAL_DRIVE", geometry, params)
    controller = FACTORIES[name](robot)
    controller.set_path(straight_path())
    res = run_closed_loop(controller, robot, World([(2.0, 0.0, 0.15)]), (0.0, 0.0, 0.0), max_steps=600)
    assert res.reached and res.min_clearance > 0.0
