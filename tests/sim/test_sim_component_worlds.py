"""Simulator worlds: the house map matches the simulated walls, the person is a person, bad
configs fail at definition."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos import Topic
from emos import msgs as M

pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")

pytestmark = pytest.mark.sim


def _grid_ranges(grid, x: float, y: float, angles: np.ndarray, range_max: float) -> np.ndarray:
    """Reference ray cast on the occupancy grid: march each ray in 1/5-cell steps."""
    res = grid.resolution
    ox, oy, _ = grid.origin
    steps = np.arange(0.0, range_max, res / 5)
    px = x + np.cos(angles)[:, None] * steps[None, :]
    py = y + np.sin(angles)[:, None] * steps[None, :]
    col = np.floor((px - ox) / res).astype(int)
    row = np.floor((py - oy) / res).astype(int)
    inside = (row >= 0) & (row < grid.data.shape[0]) & (col >= 0) & (col < grid.data.shape[1])
    hit = np.zeros_like(inside)
    hit[inside] = grid.data[row[inside], col[inside]] >= 65
    first = np.where(hit.any(axis=1), hit.argmax(axis=1), len(steps) - 1)
    return steps[first]


@pytest.mark.parametrize("world_name", ["house", "map"])
def test_house_walls_match_the_shipped_map(world_name):
    """Lidar ranges in the simulated house (built from shapes, or extruded from the map YAML)
    equal a ray cast on the map the MapServer loads: a plan on the map fits the walls."""
    from emos.actors.nav.maps import load_map
    from emos.actors.sim import Lidar, LidarConfig, SimClock, World
    from emos.actors.sim.data import HOUSE_MAP

    grid = load_map(HOUSE_MAP)
    clock = SimClock(mode="lockstep")
    world = World.demo_house(clock=clock) if world_name == "house" else World.from_map(str(HOUSE_MAP), clock=clock)
    try:
        poses = [(1.5, 1.5, 0.0), (2.55, 5.0, 1.0), (6.0, 6.0, 2.5), (6.0, 3.0, 0.3), (8.0, 2.5, -1.2)]
        errors = []
        for i, pose in enumerate(poses):
            robot = world.add_robot("turtlebot3", pose, name=f"r{i}")
            # Above the robots' bodies so they do not see each other; below every obstacle's top.
            lidar = world.add_sensor(Lidar(robot, LidarConfig(fov_deg=360, beams=720, range_max=12.0, rate_hz=100.0, mount_z=0.45)))
            world.step()
            scan = lidar.latest
            angles = pose[2] + scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))
            expected = _grid_ranges(grid, pose[0], pose[1], angles, 12.0)
            errors.append(np.abs(np.asarray(scan.ranges) - expected))
        err = np.concatenate(errors)
        # Cell-centre rasterization moves a wall face by at most half a cell (2.5 cm); beams
        # grazing a corner may differ more.
        assert np.median(err) < 0.03
        assert np.percentile(err, 95) < 0.06
    finally:
        world.close()


def test_shipped_house_map_is_the_rasterized_house():
    from emos.actors.nav.maps import load_map
    from emos.actors.sim.data import HOUSE_MAP
    from emos.actors.sim.data.generate_house_map import house_grid

    shipped, generated = load_map(HOUSE_MAP), house_grid()
    assert np.array_equal(shipped.data, generated.data)
    assert shipped.resolution == generated.resolution and tuple(shipped.origin) == tuple(generated.origin)
    # Doorways a robot fits through, the same in the map as in the world (0.98 m clear).
    res, (ox, oy, _) = shipped.resolution, shipped.origin
    occupied = shipped.data >= 65

    def gap(cells: np.ndarray, coords: np.ndarray, lo: float, hi: float) -> float:
        free = coords[(~cells) & (coords > lo) & (coords < hi)]
        return float(free.max() - free.min() + res)

    ys = oy + (np.arange(occupied.shape[0]) + 0.5) * res
    xs = ox + (np.arange(occupied.shape[1]) + 0.5) * res
    middle = gap(occupied[:, int((5.0 - ox) / res)], ys, 2.0, 3.9)
    west = gap(occupied[int((4.0 - oy) / res), :], xs, 1.0, 4.0)
    east = gap(occupied[int((4.0 - oy) / res), :], xs, 6.5, 9.5)
    for width in (middle, west, east):
        assert width == pytest.approx(1.0, abs=0.051)  # 0.98 m rounded to whole cells


def test_the_local_detector_sees_the_walking_person_and_loses_it_behind_the_wall():
    pytest.importorskip("cv2", reason="the local detector needs OpenCV (emos[agents])")
    import io

    from PIL import Image

    from emos.actors.agents.local.vision import LocalDetector
    from emos.actors.sim import Camera, CameraConfig, Lidar, LidarConfig, SimClock
    from emos.actors.sim.component.publishing import jpeg as frame_jpeg
    from emos.actors.sim.person import PERSON_RADIUS, house_with_person

    world = house_with_person(clock=SimClock(mode="lockstep"))
    detector = LocalDetector(labels=("person",))
    try:
        robot = world.add_robot("jackal", (1.5, 1.5, 0.0))
        camera = world.add_sensor(Camera(robot, CameraConfig(rate_hz=10.0)))
        lidar = world.add_sensor(Lidar(robot, LidarConfig(fov_deg=360, beams=720, rate_hz=10.0)))
        person = world.movers[0]
        seen, centre = {}, {}
        for t in (1.0, 3.0, 8.0):  # right of the view's centre, left of it, in the east room
            world.run_for(t - world.clock.now())
            # Through the JPEG the Simulator publishes on a CompressedImage topic, as a Vision
            # component subscribed to /image_raw/compressed receives it.
            jpeg = frame_jpeg(camera.latest, 85)
            seen[t] = detector.detect(np.asarray(Image.open(io.BytesIO(jpeg.data.tobytes()))))
            if seen[t]:
                x1, _, x2, _ = seen[t][0].box
                centre[t] = (x1 + x2) / 2
            if t == 3.0:
                # The lidar hits the person's body (a cylinder, not the flat billboard).
                px, py, _ = person.pose_at(world.clock.now())
                bearing = math.atan2(py - 1.5, px - 1.5)
                scan = lidar.latest
                beam = int(round((bearing - scan.angle_min) / scan.angle_increment))
                assert scan.ranges[beam] == pytest.approx(math.hypot(px - 1.5, py - 1.5) - PERSON_RADIUS, abs=0.05)
        for t in (1.0, 3.0):
            assert len(seen[t]) == 1 and seen[t][0].label == "person" and seen[t][0].score > 0.6, (t, seen[t])
        assert person.pose_at(1.0)[1] < 1.5 < person.pose_at(3.0)[1]
        assert centre[1.0] > 160 > centre[3.0]  # +y is to the camera's left
        assert seen[8.0] == []
    finally:
        world.close()


@pytest.mark.parametrize("kwargs, match", [
    (dict(world="mars"), "unknown world 'mars'"),
    (dict(world="/nowhere/house.yaml"), "map file '/nowhere/house.yaml' does not exist"),
    (dict(robot="r2d2"), "unknown robot 'r2d2'"),
    (dict(scan_rate=-1.0), "scan_rate must be a rate in Hz > 0"),
    (dict(odom_rate=0), "odom_rate must be a rate in Hz > 0"),
    (dict(clock_mode="sometimes"), "sometimes"),
    (dict(physics_rate=100.0, clock_rate=30.0), "whole multiple"),
    (dict(spawn=(1.0, "a", 0.0)), "spawn must be"),
    (dict(lockstep_consumers="driver"), "list of component names"),
])
def test_bad_simulator_config_fails_at_definition(kwargs, match):
    from emos.actors.sim import SimulatorConfig

    with pytest.raises(ValueError, match=match):
        SimulatorConfig(**kwargs)


def test_bad_simulator_wiring_fails_at_definition(tmp_path):
    from emos.actors.sim import Simulator, SimulatorConfig

    sim = Simulator("sim")
    with pytest.raises(TypeError, match="output 'scan' accepts LaserScan, but topic '/odom' is Odometry"):
        sim.outputs(scan=Topic(name="/odom", msg_type="Odometry"))
    with pytest.raises(TypeError, match="input 'command' accepts Twist or TwistStamped or TwistArray"):
        sim.inputs(command=Topic(name="/cmd", msg_type="String"))
    with pytest.raises(KeyError, match="has no output key 'lidar'"):
        sim.outputs(lidar=Topic(name="/scan", msg_type="LaserScan"))
    with pytest.raises(ValueError, match="scan_rate"):
        sim.config.scan_rate = -5.0  # validated on set, too
    bad_yaml = tmp_path / "map.yaml"
    bad_yaml.write_text("image: missing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
                        "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    with pytest.raises(ValueError, match="missing.pgm"):
        SimulatorConfig(world=str(bad_yaml))
    with pytest.raises(TypeError, match="must be a SimulatorConfig"):
        from emos.config import BaseComponentConfig

        Simulator("sim2", config=BaseComponentConfig())


def test_command_follower_twist_array_timeout_and_bad_values():
    from emos.actors.sim.component.commands import CommandFollower

    follower = CommandFollower(timeout=0.5, array_step=0.1)
    assert follower.target(0.0).tolist() == [0.0, 0.0, 0.0]  # nothing received: stand still
    follower.receive(M.Twist(linear=M.Vector3(x=0.4, y=0.1), angular=M.Vector3(z=0.2)), now=1.0)
    assert follower.target(1.5).tolist() == [0.4, 0.1, 0.2]
    assert follower.target(1.51).tolist() == [0.0, 0.0, 0.0]  # stale
    array = M.TwistArray(linear_velocities=np.array([[0.1, 0, 0], [0.2, 0, 0], [0.3, 0, 0]]),
                         angular_velocities=np.array([[0, 0, 0.5], [0, 0, 0.6], [0, 0, 0.7]]))
    follower.receive(array, now=2.0)
    assert [follower.target(t)[0] for t in (2.0, 2.15, 2.25, 2.31)] == [0.1, 0.2, 0.3, 0.0]
    with pytest.raises(ValueError, match="non-finite"):
        follower.receive(M.Twist(linear=M.Vector3(x=float("nan"))), now=3.0)
    with pytest.raises(TypeError, match="Twist, TwistStamped or TwistArray"):
        follower.receive(M.String(data="go"), now=3.0)


def test_launcher_robot_config_becomes_the_simulated_robot():
    """``launcher.robot`` reaches the Simulator: it simulates the robot navigation plans for."""
    from emos import Launcher
    from emos.actors.nav.robot import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType
    from emos.actors.sim import SimClock, Simulator, World
    from emos.actors.sim.component.robot_model import resolve_robot

    my_robot = RobotConfig(  # the point-navigation recipe's robot
        model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
        geometry_params=np.array([0.1, 0.3]),
        ctrl_vx_limits=LinearCtrlLimits(max_vel=0.4, max_acc=1.5, max_decel=2.5),
        ctrl_omega_limits=AngularCtrlLimits(max_vel=0.4, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3))
    sim = Simulator("sim")
    launcher = Launcher()
    launcher.add_pkg(components=[sim])
    launcher.robot = my_robot
    launcher._apply_shared()  # what bringup does first
    assert sim.config.robot is my_robot
    spec = resolve_robot(sim.config.robot)
    assert (spec.radius, spec.height, spec.max_vx, spec.max_omega) == (0.1, 0.3, 0.4, 0.4)
    world = World(clock=SimClock(mode="lockstep"))
    try:
        world.add_wall((2.0, -1.0), (2.0, 1.0), thickness=0.1)
        robot = world.add_robot(spec, (0.0, 0.0, 0.0))
        robot.command(1.0)  # above its limit
        world.run_for(1.0)
        assert robot.twist[0] == pytest.approx(0.4)
        world.run_for(6.0)
        assert robot.collided  # a cylinder of radius 0.1 stops at the wall face (x = 1.95)
        assert robot.pose[0] + 0.1 == pytest.approx(1.95, abs=0.01)
    finally:
        world.close()


def test_simulator_config_file_sets_parameters_frames_and_keyed_topics(tmp_path):
    from emos.actors.sim import Simulator

    path = tmp_path / "sim.yaml"
    path.write_text("""
sim:
  world: empty
  robot: holonomic
  spawn: [1.0, 2.0, 0.5]
  clock_mode: lockstep
  lockstep_consumers: [driver]
  frames: {odom: odom, robot_base: base_footprint, scan: laser}
  outputs:
    odom: {name: /odometry/filtered, msg_type: Odometry}
""")
    sim = Simulator("sim", config_file=str(path))
    cfg = sim.config
    assert (cfg.world, cfg.robot, cfg.spawn, cfg.clock_mode.value, cfg.lockstep_consumers) == (
        "empty", "holonomic", (1.0, 2.0, 0.5), "lockstep", ["driver"])
    assert (cfg.frames.world, cfg.frames.robot_base, cfg.frames.scan) == ("map", "base_footprint", "laser")
    assert sim.get_out_topic("odom").name == "/odometry/filtered"
    assert [t.name for t in sim.out_topics] == ["/odometry/filtered", "/scan", "/tf", "/clock"]
    path.write_text("sim:\n  outputs:\n    lidar: {name: /scan, msg_type: LaserScan}\n")
    with pytest.raises(ValueError, match="has no output key 'lidar'"):
        Simulator("sim", config_file=str(path))
    path.write_text("sim:\n  frames: {odom: odom, base: base_link}\n")
    with pytest.raises(ValueError, match="unknown parameter.*sim.frames.base"):
        Simulator("sim", config_file=str(path))


def test_tf_tree_composes_to_the_true_pose_and_skips_an_odom_frame_equal_to_the_world():
    from emos.actors.nav.robot import RobotFrames
    from emos.actors.sim.component.publishing import quaternion_from_matrix, tf_tree
    from emos.actors.sim.sensors.odometry import OdometryReading

    def yaw_of(q) -> float:
        return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y ** 2 + q.z ** 2))

    drifted = OdometryReading(2.0, "odom", "base_link", 1.0, 0.5, 0.3, 0.0, 0.0, 0.0)  # odometry's belief
    true_pose = np.array([1.2, 0.4, 0.25])
    tree = tf_tree(RobotFrames(), drifted, true_pose, None, None)
    (world_odom, odom_base) = tree.transforms
    assert (world_odom.header.frame_id, world_odom.child_frame_id) == ("map", "odom")
    # Compose map->odom with odom->base: the true pose.
    a = world_odom.transform
    ax, ay, ayaw = a.translation.x, a.translation.y, yaw_of(a.rotation)
    bx, by, byaw = odom_base.transform.translation.x, odom_base.transform.translation.y, yaw_of(odom_base.transform.rotation)
    composed = (ax + math.cos(ayaw) * bx - math.sin(ayaw) * by, ay + math.sin(ayaw) * bx + math.cos(ayaw) * by, ayaw + byaw)
    assert np.allclose(composed, true_pose)
    assert odom_base.header.stamp.to_sec() == pytest.approx(2.0)
    # The spec's recipe uses odom="map": then there is no map->odom edge.
    tree = tf_tree(RobotFrames(world="map", odom="map"), drifted, true_pose, None, None)
    assert [(t.header.frame_id, t.child_frame_id) for t in tree.transforms] == [("map", "base_link")]
    # Rotation matrices of every kind round-trip through quaternions.
    rng = np.random.default_rng(3)
    for _ in range(50):
        q = rng.standard_normal(4)
        q /= np.linalg.norm(q)
        x, y, z, w = q
        r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        back = np.array(quaternion_from_matrix(r))
        assert np.allclose(back, q) or np.allclose(back, -q)
