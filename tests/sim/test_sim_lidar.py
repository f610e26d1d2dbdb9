import math

import numpy as np
import pytest

from emos.actors.sim import Lidar, LidarConfig, Wall

pytestmark = pytest.mark.sim


def test_lidar_facing_a_wall_matches_the_analytic_range(make_world):
    world = make_world()
    world.add(Wall((3.0, -10.0), (3.0, 10.0), thickness=0.2))  # face at x = 2.9
    robot = world.add_robot("jackal", (0.0, 0.0, 0.0))
    lidar = world.add_sensor(Lidar(robot, LidarConfig(fov_deg=120, beams=121)))
    world.step()
    scan = lidar.latest
    angles = scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))
    expected = 2.9 / np.cos(angles)
    assert scan.ranges.dtype == np.float32
    np.testing.assert_allclose(scan.ranges, expected, atol=2e-3)
    assert scan.angle_min == pytest.approx(-math.radians(60))
    assert scan.angle_max == pytest.approx(math.radians(60))


def test_lidar_mount_pose_and_robot_heading_shift_the_ranges(make_world):
    world = make_world()
    world.add(Wall((-10.0, 4.0), (10.0, 4.0), thickness=0.2))  # face at y = 3.9
    robot = world.add_robot("jackal", (0.0, 0.0, math.pi / 2))  # facing +y
    cfg = LidarConfig(fov_deg=10, beams=11, mount_xy=(0.5, 0.0))  # 0.5 m ahead of the base
    lidar = world.add_sensor(Lidar(robot, cfg))
    world.step()
    centre = lidar.latest.ranges[5]
    assert centre == pytest.approx(3.9 - 0.5, abs=2e-3)


def test_lidar_reports_no_return_as_inf_and_never_sees_its_own_robot(make_world):
    world = make_world()
    world.add_box((2.0, 0.0), (0.4, 0.4))  # near face at 1.8
    robot = world.add_robot("jackal", (0.0, 0.0, 0.0))
    lidar = world.add_sensor(Lidar(robot, LidarConfig(fov_deg=360, beams=360, range_max=5.0, mount_z=0.1)))
    world.step()
    r = lidar.latest.ranges
    # The beam straight ahead (index 180 of a full circle starting at -pi) hits the box.
    assert r[180] == pytest.approx(1.8, abs=2e-3)
    # Everything else escapes: the robot's own body (the rays start inside it) is not seen.
    others = np.delete(r, range(170, 191))
    assert np.all(np.isinf(others))


@pytest.mark.parametrize("geometry", ["cylinder", "box"])
def test_a_lidar_in_the_plane_of_its_bodys_top_face_never_sees_its_own_robot(make_world, geometry):
    """A navigation RobotConfig's body (actors/sim/component/robot_model.py) puts the scan plane
    on its top face: Bullet reported about half the rays as hits at their start inside the
    body, ranges of range_min that a consumer drops, so the robot saw with half its beams."""
    from emos.actors.nav import RobotConfig, RobotGeometry, RobotType
    from emos.actors.sim.component.robot_model import spec_from_robot_config

    kind, params = ((RobotGeometry.Type.CYLINDER, [0.2, 0.3]) if geometry == "cylinder" else (RobotGeometry.Type.BOX, [0.4, 0.4, 0.3]))
    spec = spec_from_robot_config(RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=kind,
                                              geometry_params=np.array(params)))
    for yaw in (0.0, 0.3, 1.1):
        world = make_world()
        world.add_box((2.0, 0.0), (0.4, 0.4))  # near face at 1.8
        robot = world.add_robot(spec, (0.0, 0.0, yaw))
        lidar = world.add_sensor(Lidar(robot, LidarConfig(fov_deg=360, beams=360, range_max=5.0, mount_z=spec.lidar_height)))
        world.step()
        r = lidar.latest.ranges
        ahead = int(round((math.pi - yaw) / math.radians(1.0)))  # the beam pointing along world +x
        assert r[ahead] == pytest.approx(1.8, abs=2e-3)
        others = np.delete(r, range(ahead - 10, ahead + 11))
        assert np.all(np.isinf(others)), f"yaw {yaw}: {int(np.sum(np.isfinite(others)))} beams hit, least {np.nanmin(others):.3f} m"


def test_lidar_to_cylinder_and_world_points(make_world):
    world = make_world()
    world.add_cylinder((0.0, 2.0), radius=0.3)
    robot = world.add_robot("jackal", (0.0, 0.0, math.pi / 2))
    lidar = world.add_sensor(Lidar(robot, LidarConfig(fov_deg=2, beams=3)))
    world.step()
    assert lidar.latest.ranges[1] == pytest.approx(1.7, abs=0.3 * 0.02 + 1e-3)  # 16-gon, < 2 % of r
    pts = lidar.latest.world_points()
    assert pts[1] == pytest.approx([0.0, 1.7], abs=0.01)


def test_lidar_noise_is_seeded(make_world):
    def scan(seed):
        world = make_world(seed=seed)
        world.add(Wall((3.0, -10.0), (3.0, 10.0)))
        robot = world.add_robot("jackal", (0.0, 0.0, 0.0))
        lidar = world.add_sensor(Lidar(robot, LidarConfig(fov_deg=60, beams=61, noise_std=0.02)))
        world.step()
        return lidar.latest.ranges

    a, b, c = scan(1), scan(1), scan(2)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert 0.005 < np.std(a - 2.95 / np.cos(np.radians(np.arange(-30, 31)))) < 0.05


@pytest.mark.parametrize("kwargs", [dict(beams=1), dict(fov_deg=0), dict(fov_deg=400), dict(range_min=5, range_max=1),
                                    dict(noise_std=-1), dict(rate_hz=0)])
def test_lidar_config_rejects_bad_values(kwargs):
    with pytest.raises(ValueError, match="LidarConfig"):
        LidarConfig(**kwargs)


def test_lidar_sees_a_moving_obstacle_where_its_path_puts_it(make_world):
    from emos.actors.sim import Box, MovingObstacle

    world = make_world()
    mover = MovingObstacle(Box((0, 0), (0.4, 0.4)), waypoints=[(3.0, -4.0), (3.0, 4.0)], speed=2.0, mode="once")
    world.add(mover)
    robot = world.add_robot("jackal", (0.0, 0.0, 0.0))
    lidar = world.add_sensor(Lidar(robot, LidarConfig(fov_deg=2, beams=3, rate_hz=100)))
    world.step()
    assert np.isinf(lidar.latest.ranges[1])  # still 4 m away from the beam
    world.run_for(2.0 - world.clock.now())  # the box centre crosses y = 0 at t = 2 s
    assert lidar.latest.ranges[1] == pytest.approx(3.0 - 0.2, abs=2e-3)
    world.run_for(1.0)
    assert np.isinf(lidar.latest.ranges[1])
