"""Controllers with every obstacle input type, bad scan values, ids, configs, rotate-then-move."""
import math

import numpy as np
import pytest

from emos.actors.nav.controllers import (
    DVZ,
    DWA,
    ControllersID,
    DVZConfig,
    DWAConfig,
    LaserScan2D,
    OccupancyGrid2D,
    PurePursuit,
    PurePursuitConfig,
    Stanley,
    StanleyConfig,
    VisionRGBDFollowerConfig,
    VisionRGBFollowerConfig,
)
from emos.actors.nav.controllers.base import ControlStatus
from emos.actors.nav.controllers.dvz import deformation
from emos.actors.nav.controllers.sensors import obstacle_points
from emos.actors.nav.costs import TrajectoryCostsWeights
from emos.actors.nav.kinematics import integrate
from emos.actors.nav.local_map import LocalMapper, MapConfig

from .sim2d import World, make_robot, run_closed_loop, straight_path

pytestmark = pytest.mark.unit


class GridWorld(World):
    """The same world, but the controller sees a local occupancy grid built from the scan."""

    def __init__(self, circles):
        super().__init__(circles)
        self.mapper = LocalMapper(MapConfig(width=6.0, height=6.0, resolution=0.05))

    def scan(self, pose):
        grid = self.mapper.update(super().scan(pose))
        return OccupancyGrid2D(grid.copy(), 0.05, self.mapper.origin)


class CloudWorld(World):
    """Obstacles as an (N, 3) point cloud with NaN rows and points above the robot."""

    def scan(self, pose):
        pts = super().scan(pose).points()
        z = np.full((pts.shape[0], 1), 0.2)
        cloud = np.hstack([pts, z])
        junk = np.array([[np.nan, 0.0, 0.2], [0.5, 0.0, np.inf]])
        return np.vstack([cloud, junk])


@pytest.mark.parametrize("world_cls", [GridWorld, CloudWorld])
@pytest.mark.parametrize("factory", [DWA, PurePursuit, DVZ])
def test_grid_and_point_cloud_inputs_avoid_the_obstacle(world_cls, factory):
    robot = make_robot("DIFFERENTIAL_DRIVE")
    controller = factory(robot)
    controller.set_path(straight_path())
    res = run_closed_loop(controller, robot, world_cls([(2.0, 0.0, 0.15)]), (0.0, 0.0, 0.0), max_steps=600)
    assert res.reached and res.min_clearance > 0.0


def test_obstacle_points_drops_nan_and_inf():
    scan = LaserScan2D(np.array([1.0, np.nan, np.inf, -1.0, 0.01]), range_min=0.05, range_max=5.0)
    pts = obstacle_points(scan)
    assert pts.shape == (1, 2)
    with pytest.raises(ValueError, match="point array"):
        obstacle_points(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="one per range"):
        LaserScan2D(np.ones(3), angles=np.zeros(2))


@pytest.mark.parametrize("factory", [DWA, PurePursuit, DVZ, Stanley])
def test_scans_full_of_nan_and_inf_are_no_obstacles(factory):
    robot = make_robot("DIFFERENTIAL_DRIVE")
    controller = factory(robot)
    controller.set_path(straight_path(2.0))
    pose, vel = np.zeros(3), np.zeros(3)
    rng = np.random.default_rng(3)
    for _ in range(300):
        ranges = np.where(rng.random(360) < 0.5, np.nan, np.inf)
        res = controller.compute(pose, vel, LaserScan2D(ranges, range_max=5.0))
        assert np.all(np.isfinite(res.commands))
        if res.status is ControlStatus.GOAL_REACHED:
            break
        vel = res.command
        pose = integrate(pose, vel, 0.1)
    assert res.status is ControlStatus.GOAL_REACHED


@pytest.mark.parametrize("factory", [DWA, PurePursuit, Stanley])
@pytest.mark.parametrize("model", ["DIFFERENTIAL_DRIVE", "OMNI"])
def test_rotate_then_move_when_facing_away(factory, model):
    robot = make_robot(model)
    controller = factory(robot)
    controller.set_path(straight_path())
    res = run_closed_loop(controller, robot, World(), (0.0, 0.0, math.pi), max_steps=400)
    assert res.reached
    first = res.statuses[:5]
    assert all(s == "rotating" for s in first), first
    # while rotating the robot stays (nearly) where it is
    assert np.hypot(*res.poses[5][:2]) < 0.05


def test_controllers_id_values_and_lookup():
    assert ControllersID.DWA.value == "DWA"
    assert ControllersID.from_any("Stanley") is ControllersID.STANLEY
    assert ControllersID.from_any("PURE_PURSUIT") is ControllersID.PURE_PURSUIT
    assert ControllersID.from_any("VisionRGBDFollower") is ControllersID.VISION_DEPTH
    with pytest.raises(ValueError, match="DWA"):
        ControllersID.from_any("MPC")


def test_config_defaults_match_the_spec():
    dwa = DWAConfig()
    assert (dwa.control_time_step, dwa.prediction_horizon, dwa.control_horizon) == (0.1, 1.0, 0.2)
    assert (dwa.max_linear_samples, dwa.max_angular_samples, dwa.octree_resolution, dwa.max_num_threads) == (20, 20, 0.1, 1)
    assert dwa.costs_weights == TrajectoryCostsWeights()
    pp = PurePursuitConfig()
    assert (pp.lookahead_gain_forward, pp.prediction_horizon, pp.path_search_step, pp.max_search_candidates) == (0.8, 10, 0.2, 10)
    st = StanleyConfig()
    assert (st.heading_gain, st.cross_track_min_linear_vel, st.min_angular_vel, st.cross_track_gain,
            st.max_angle_error, st.max_distance_error) == (0.7, 0.05, 0.01, 1.5, np.pi / 16, 0.1)
    dvz = DVZConfig()
    assert (dvz.min_front_margin, dvz.K_linear, dvz.K_angular, dvz.K_I, dvz.side_margin_width_ratio,
            dvz.heading_gain, dvz.cross_track_gain) == (1.0, 1.0, 1.0, 5.0, 1.0, 0.7, 1.5)
    rgb = VisionRGBFollowerConfig()
    assert (rgb.rotation_gain, rgb.speed_gain, rgb.tolerance, rgb.target_search_timeout, rgb.enable_search,
            rgb.min_vel) == (1.0, 0.7, 0.1, 30.0, True, 0.1)
    rgbd = VisionRGBDFollowerConfig()
    assert (rgbd.target_distance, rgbd.target_orientation, rgbd.prediction_horizon, rgbd.target_search_timeout,
            rgbd.depth_conversion_factor) == (None, 0.0, 10, 30.0, 1e-3)
    np.testing.assert_array_equal(rgbd.camera_position_to_robot, [0, 0, 0])


@pytest.mark.parametrize("make,match", [
    (lambda: DWAConfig(max_linear_samples=0), "max_linear_samples"),
    (lambda: DWAConfig(control_time_step=0.0), "control_time_step"),
    (lambda: DWAConfig(sensor_rotation_to_robot=[0, 0, 1]), "4 finite numbers"),
    (lambda: PurePursuitConfig(max_search_candidates=0), "max_search_candidates"),
    (lambda: StanleyConfig(max_angle_error=4.0), "max_angle_error"),
    (lambda: DVZConfig(K_I=20.0), "K_I"),
    (lambda: VisionRGBFollowerConfig(tolerance=2.0), "tolerance"),
])
def test_bad_config_values_name_the_field(make, match):
    with pytest.raises((ValueError, TypeError), match=match):
        make()


def test_config_validates_on_assignment_too():
    cfg = DWAConfig()
    with pytest.raises(ValueError, match="prediction_horizon"):
        cfg.prediction_horizon = -1.0


def test_dvz_deformation_analytic():
    # nothing inside the zone: no deformation
    assert deformation(np.zeros((0, 2)), 1.0, 1.0)[0] == 0.0
    # one point dead ahead at half the zone radius deforms one of 72 bins by 0.5
    intensity, theta, w = deformation(np.array([[0.5, 0.0]]), 1.0, 1.0, bins=72)
    assert intensity == pytest.approx(0.5 / 72)
    assert theta == pytest.approx(0.0, abs=0.05)
    # an obstacle on the left gives a deformation angle on the left
    _, theta, _ = deformation(np.array([[0.0, 0.4], [0.05, 0.4]]), 1.0, 1.0)
    assert theta == pytest.approx(math.pi / 2, abs=0.1)


@pytest.mark.parametrize("factory", [DWA, PurePursuit, DVZ, Stanley])
def test_non_finite_robot_state_is_a_clear_error(factory):
    controller = factory(make_robot("DIFFERENTIAL_DRIVE"))
    controller.set_path(straight_path())
    with pytest.raises(ValueError, match="pose"):
        controller.compute(np.array([np.nan, 0.0, 0.0]), np.zeros(3))
    with pytest.raises(ValueError, match="velocity"):
        controller.compute(np.zeros(3), np.zeros(2))


def test_bad_path_is_a_clear_error():
    controller = DWA(make_robot("OMNI"))
    with pytest.raises(ValueError, match="path"):
        controller.set_path(np.array([[0.0, 0.0], [np.inf, 1.0]]))
    with pytest.raises(ValueError, match="path"):
        controller.set_path(np.zeros((5, 4)))


def test_small_closed_loop_is_not_done_at_its_start():
    from emos.actors.nav.controllers.path import PathProgress, ReferencePath

    th = np.linspace(-math.pi / 2, 1.5 * math.pi, 60)
    loop = np.stack([0.2 * np.cos(th), 0.2 + 0.2 * np.sin(th)], 1)  # 1.26 m long, ends where it starts
    progress = PathProgress(ReferencePath(loop), search_ahead=0.3)
    progress.update(np.zeros(3))
    assert not progress.goal_reached(np.zeros(3), 0.1)
    for pose in loop[::3]:
        progress.update(np.array([pose[0], pose[1], 0.0]))
    progress.update(np.zeros(3))
    assert progress.goal_reached(np.zeros(3), 0.1)


def test_make_controller_by_id():
    from emos.actors.nav.controllers import CameraIntrinsics, make_controller

    robot = make_robot("DIFFERENTIAL_DRIVE")
    assert isinstance(make_controller("DWA", robot), DWA)
    pp = make_controller(ControllersID.PURE_PURSUIT, robot, PurePursuitConfig(lookahead_gain_forward=0.5))
    assert pp.config.lookahead_gain_forward == 0.5
    with pytest.raises(TypeError, match="expected StanleyConfig"):
        make_controller("Stanley", robot, DWAConfig())
    with pytest.raises(TypeError, match="intrinsics"):
        make_controller("VisionRGBDFollower", robot)
    rgbd = make_controller("VisionRGBDFollower", robot, intrinsics=CameraIntrinsics(500, 500, 320, 240))
    assert rgbd.intrinsics.fx == 500
