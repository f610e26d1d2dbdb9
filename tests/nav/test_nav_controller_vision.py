"""Vision followers in closed loop with a synthetic pinhole camera and depth image."""
import math

import numpy as np
import pytest

from emos.actors.nav.controllers import (
    BoundingBox,
    CameraIntrinsics,
    VisionRGBDFollower,
    VisionRGBDFollowerConfig,
    VisionRGBFollower,
    VisionRGBFollowerConfig,
)
from emos.actors.nav.controllers.base import ControlStatus
from emos.actors.nav.controllers.vision_rgbd import target_from_depth
from emos.actors.nav.kinematics import integrate, to_robot_frame, wrap_angle

from .sim2d import World, make_robot

pytestmark = pytest.mark.unit

K = CameraIntrinsics(fx=500.0, fy=500.0, cx=320.0, cy=240.0)
W, H = 640, 480
CAM_Z = 0.5  # camera height above the floor
PERSON = (0.5, 1.0)  # width, height (m): fits the image from 1 m on


def camera(pose, target):
    """Bounding box and a uint16 depth image (mm) of a box-shaped person at world ``target``."""
    xr, yr = to_robot_frame(pose, np.asarray(target, dtype=float))
    if xr < 0.2:
        return None, np.zeros((H, W), np.uint16)

    def u(y):  # image column of a point at lateral offset y
        return K.fx * (-y) / xr + K.cx

    def v(z):  # image row of a point at height z
        return K.fy * (CAM_Z - z) / xr + K.cy

    u0, u1 = u(yr + PERSON[0] / 2), u(yr - PERSON[0] / 2)
    v0, v1 = v(PERSON[1]), v(0.0)
    u0c, u1c, v0c, v1c = max(u0, 0), min(u1, W), max(v0, 0), min(v1, H)
    if u1c - u0c < 2 or v1c - v0c < 2:
        return None, np.zeros((H, W), np.uint16)
    depth = np.zeros((H, W), np.uint16)
    depth[int(v0c):int(v1c), int(u0c):int(u1c)] = int(round(xr * 1000))
    return BoundingBox(u0c, v0c, u1c - u0c, v1c - v0c, W, H), depth


def test_back_projection_recovers_target_position():
    box, depth = camera(np.zeros(3), (2.0, 0.4))
    body = target_from_depth(box, depth, K, 1e-3)
    np.testing.assert_allclose(body[:2], [2.0, 0.4], atol=0.01)
    # depth holes (0) and NaN are ignored; an all-invalid patch gives no target
    depth_f = depth.astype(float)
    depth_f[depth_f > 0][::2] = np.nan
    assert target_from_depth(box, np.zeros_like(depth), K, 1e-3) is None


@pytest.mark.parametrize("model", ["DIFFERENTIAL_DRIVE", "OMNI", "ACKERMANN"])
def test_rgb_follower_centres_and_restores_distance_after_target_moves(model):
    robot = make_robot(model)
    follower = VisionRGBFollower(robot, VisionRGBFollowerConfig())
    pose, vel = np.zeros(3), np.zeros(3)
    target = np.array([2.0, 0.6])
    start_distance = np.hypot(*target)
    max_gap = 0.0
    for step in range(300):
        box, _ = camera(pose, target)
        assert box is not None, f"lost the target at step {step}"
        res = follower.compute(box, vel, pose)
        vel = res.command
        pose = integrate(pose, vel, 0.1)
        if step < 100:  # walks away sideways at ~0.16 m/s for 10 s, then stands
            target = target + np.array([0.1, 0.12]) * 0.1
        max_gap = max(max_gap, np.hypot(*(target - pose[:2])) - start_distance)
    box, _ = camera(pose, target)
    assert abs(box.horizontal_error) <= 0.1 + 0.02  # centred within the tolerance
    # Box size within the 10 % tolerance means distance within about 10 %.
    assert abs(np.hypot(*(target - pose[:2])) / start_distance - 1.0) < 0.15
    assert max_gap < 1.5  # it followed while the target moved


def test_rgb_follower_searches_towards_last_side_then_gives_up():
    robot = make_robot("DIFFERENTIAL_DRIVE")
    cfg = VisionRGBFollowerConfig(target_search_pause=3, target_search_timeout=2.0)
    follower = VisionRGBFollower(robot, cfg)
    pose = np.zeros(3)
    box, _ = camera(pose, (2.0, 1.0))  # seen on the left
    follower.compute(box)
    statuses, commands = [], []
    for _ in range(40):
        res = follower.compute(None)
        statuses.append(res.status)
        commands.append(res.commands[-1])
    assert statuses[:3] == [ControlStatus.WAITING] * 3
    assert all(np.allclose(c, 0) for c in commands[:3])
    assert statuses[3] is ControlStatus.SEARCHING and commands[10][2] > 0  # rotates left
    assert statuses[-1] is ControlStatus.LOST and np.allclose(commands[-1], 0)


def test_rgb_follower_search_finds_target_again():
    robot = make_robot("DIFFERENTIAL_DRIVE")
    follower = VisionRGBFollower(robot, VisionRGBFollowerConfig(target_search_pause=1))
    pose, vel = np.zeros(3), np.zeros(3)
    follower.compute(camera(pose, (2.0, 0.3))[0])
    target = np.array([0.0, 2.0])  # jumped out of view, to the left
    found = False
    for _ in range(100):
        box, _ = camera(pose, target)
        res = follower.compute(box, vel, pose)
        if box is not None:
            found = True
            break
        vel = res.command
        pose = integrate(pose, vel, 0.1)
    assert found


def test_rgb_follower_without_search_reports_lost():
    follower = VisionRGBFollower(make_robot("OMNI"), VisionRGBFollowerConfig(enable_search=False, target_search_pause=0))
    follower.compute(camera(np.zeros(3), (2.0, 0.0))[0])
    res = follower.compute(None)
    assert res.status is ControlStatus.LOST and np.allclose(res.commands, 0)


def _run_rgbd(model, target, obstacles=(), steps=300, moving=(0.0, 0.0), distance=1.0):
    robot = make_robot(model)
    follower = VisionRGBDFollower(robot, K, VisionRGBDFollowerConfig(target_distance=distance))
    world = World(list(obstacles) + [(target[0], target[1], 0.2)])
    pose, vel = np.zeros(3), np.zeros(3)
    target = np.asarray(target, dtype=float)
    min_clear = math.inf
    obstacle_world = World(list(obstacles))
    for _ in range(steps):
        world.circles[-1] = (target[0], target[1], 0.2)
        box, depth = camera(pose, target)
        res = follower.compute(pose, vel, box, depth, world.scan(pose))
        vel = res.command
        pose = integrate(pose, vel, 0.1)
        target = target + np.asarray(moving) * 0.1
        if obstacles:
            from emos.actors.nav.controllers.clearance import pose_clearance
            min_clear = min(min_clear, float(pose_clearance(robot, pose[None], obstacle_world.boundary_points())[0]))
    return pose, target, min_clear


@pytest.mark.parametrize("model", ["DIFFERENTIAL_DRIVE", "OMNI", "ACKERMANN"])
def test_rgbd_follower_converges_to_target_distance(model):
    pose, target, _ = _run_rgbd(model, (3.0, 0.8))
    dist = np.hypot(*(target - pose[:2]))
    bearing = wrap_angle(math.atan2(target[1] - pose[1], target[0] - pose[0]) - pose[2])
    assert abs(dist - 1.0) < 0.2
    assert abs(bearing) < 0.3


def test_rgbd_follower_goes_around_obstacle_without_touching_it():
    pose, target, min_clear = _run_rgbd("DIFFERENTIAL_DRIVE", (3.5, 0.0), obstacles=[(1.6, 0.0, 0.25)], steps=400)
    assert abs(np.hypot(*(target - pose[:2])) - 1.0) < 0.25
    assert min_clear > 0.0


def test_rgbd_follower_tracks_moving_target():
    pose, target, _ = _run_rgbd("DIFFERENTIAL_DRIVE", (2.0, 0.0), moving=(0.2, 0.1), steps=300)
    assert abs(np.hypot(*(target - pose[:2])) - 1.0) < 0.35


def test_rgbd_config_validation():
    with pytest.raises(ValueError, match="target_distance"):
        VisionRGBDFollowerConfig(target_distance=-1.0)
    with pytest.raises(ValueError, match="depth_conversion_factor"):
        VisionRGBDFollowerConfig(depth_conversion_factor=0.0)


def test_rgbd_follower_measures_a_detection_once_while_the_robot_turns():
    """A detector slower than the control loop hands the same box over several steps. Projected
    again with the robot's newer heading, that old box would put the (still) target wherever the
    robot turned to; measured once, the target stays where it was seen."""
    follower = VisionRGBDFollower(make_robot("DIFFERENTIAL_DRIVE"), K, VisionRGBDFollowerConfig(target_distance=2.0))
    pose = np.zeros(3)
    box, depth = camera(pose, (2.0, 0.6))
    follower.compute(pose, np.zeros(3), box, depth)
    seen = follower.tracker.position.copy()
    np.testing.assert_allclose(seen, [2.0, 0.6], atol=0.05)
    turned = np.array([0.0, 0.0, 0.15])  # the robot turned towards it; the box is the old one
    follower.compute(turned, np.zeros(3), box, depth, new_measurement=False)
    np.testing.assert_allclose(follower.tracker.position, seen, atol=1e-9)
    follower.compute(turned, np.zeros(3), box, depth, new_measurement=True)  # re-measured: it moves
    assert np.hypot(*(follower.tracker.position - seen)) > 0.1  # (0.3 m off: within the gate, taken)


def test_rgbd_follower_takes_a_far_reachable_measurement_only_once_the_next_confirms_it():
    """After a gap in the detections the target could have walked far (``target_max_speed``), and
    a single false detection there would swing the robot away from the person: a measurement
    beyond ``target_gate`` but within reach is followed only once the next one agrees with it."""
    cfg = VisionRGBDFollowerConfig(target_distance=2.0)
    pose = np.zeros(3)
    follower = VisionRGBDFollower(make_robot("DIFFERENTIAL_DRIVE"), K, cfg)
    follower.compute(pose, np.zeros(3), *camera(pose, (2.0, 0.0)))
    for _ in range(10):  # a second without detections: the person may be up to 2.5 m away now
        follower.compute(pose, np.zeros(3), None, None)
    ghost = camera(pose, (2.3, 0.9))  # 0.95 m off: reachable, not near
    follower.compute(pose, np.zeros(3), *ghost)
    np.testing.assert_allclose(follower.tracker.position, [2.0, 0.0], atol=0.05)  # one alone: not taken
    follower.compute(pose, np.zeros(3), *camera(pose, (2.05, 0.0)))  # the person, where predicted
    np.testing.assert_allclose(follower.tracker.position, [2.05, 0.0], atol=0.05)
    for _ in range(10):
        follower.compute(pose, np.zeros(3), None, None)
    moved = (2.4, 0.9)  # the person really walked there during the gap: two detections agree
    follower.compute(pose, np.zeros(3), *camera(pose, moved))
    assert np.hypot(*(follower.tracker.position - [2.05, 0.0])) < 0.05
    follower.compute(pose, np.zeros(3), *camera(pose, (2.42, 0.9)))
    np.testing.assert_allclose(follower.tracker.position, [2.42, 0.9], atol=0.05)  # taken, and not blended with the old estimate


def test_rgbd_follower_projects_a_detection_from_where_the_robot_was_when_the_picture_was_taken():
    """The detector's box reaches the control step after the robot has turned on: projected with
    the step's pose it misplaces the target by that turn; projected from the pose at the
    picture's stamp (``seen_from``, from a ``PoseHistory``) it lands where the target is."""
    from emos.geometry import PoseHistory

    target = (2.0, 0.6)
    at_picture = np.array([0.0, 0.0, 0.0])
    box, depth = camera(at_picture, target)
    history = PoseHistory()
    history.add(10.0, at_picture)
    history.add(10.1, np.array([0.02, 0.0, 0.25]))  # the robot kept turning after the picture
    now = np.array([0.02, 0.0, 0.25])
    late = VisionRGBDFollower(make_robot("DIFFERENTIAL_DRIVE"), K, VisionRGBDFollowerConfig(target_distance=2.0))
    late.compute(now, np.zeros(3), box, depth)
    assert np.hypot(*(late.tracker.position - target)) > 0.4  # off by the turn made since the picture
    stamped = VisionRGBDFollower(make_robot("DIFFERENTIAL_DRIVE"), K, VisionRGBDFollowerConfig(target_distance=2.0))
    stamped.compute(now, np.zeros(3), box, depth, seen_from=history.at(10.0))
    np.testing.assert_allclose(stamped.tracker.position, target, atol=0.05)


def test_rgbd_follower_ignores_a_measurement_the_target_cannot_have_walked_to_unless_it_persists():
    """A false detection (or a box whose depth hit the wall behind) 2 m from the tracked target
    is not followed; measurements that keep agreeing with each other elsewhere are: the tracker
    starts again there after ``target_gate_misses`` of them."""
    cfg = VisionRGBDFollowerConfig(target_distance=2.0, target_gate_misses=3)
    follower = VisionRGBDFollower(make_robot("DIFFERENTIAL_DRIVE"), K, cfg)
    pose = np.zeros(3)
    box, depth = camera(pose, (2.0, 0.0))
    follower.compute(pose, np.zeros(3), box, depth)
    np.testing.assert_allclose(follower.tracker.position, [2.0, 0.0], atol=0.05)
    far_box, far_depth = camera(pose, (3.5, 1.2))  # 1.9 m away, 0.1 s later: no person walks that
    follower.compute(pose, np.zeros(3), far_box, far_depth)
    follower.compute(pose, np.zeros(3), far_box, far_depth)
    np.testing.assert_allclose(follower.tracker.position, [2.0, 0.0], atol=0.05)  # ignored twice
    follower.compute(pose, np.zeros(3), far_box, far_depth)  # the third in a row: it is there
    np.testing.assert_allclose(follower.tracker.position, [3.5, 1.2], atol=0.05)
    near_box, near_depth = camera(pose, (3.55, 1.2))  # within the gate: followed as before
    follower.compute(pose, np.zeros(3), near_box, near_depth)
    assert 3.5 < follower.tracker.position[0] < 3.56
    with pytest.raises(ValueError):
        VisionRGBDFollowerConfig(target_gate_misses=0)
