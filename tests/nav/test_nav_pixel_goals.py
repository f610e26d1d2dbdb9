"""Pixel goals (Detections / PointsOfInterest with depth) -> world goals: the transform tree,
the conversion against analytic intrinsics and against a real pybullet camera rendering, and
every bad input named."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from emos import msgs as M
from emos.actors.nav.components.convert import BadInput
from emos.actors.nav.components.pixel_goals import camera_on_base, depth_in_metres, intrinsics_of, pixel_goal_in_world, pixel_targets
from emos.actors.nav.controllers.vision_common import CameraIntrinsics
from emos.actors.nav.transforms import TransformTree, quaternion_matrix, transform_matrix

pytestmark = pytest.mark.sim

WHERE = "goal_point /grounding_output (Detections)"
# A camera 0.2 m ahead of the base and 0.4 m up, looking forward: optical x right, y down, z forward.
OPTICAL = np.c_[[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]


def _tf(parent: str, child: str, xyz, matrix3) -> M.TransformStamped:
    from emos.actors.sim.component.publishing import quaternion_from_matrix

    q = quaternion_from_matrix(np.asarray(matrix3, dtype=float))
    return M.TransformStamped(header=M.Header(frame_id=parent), child_frame_id=child,
                              transform=M.Transform(translation=M.Vector3(x=xyz[0], y=xyz[1], z=xyz[2]),
                                                    rotation=M.Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])))


def _base_from_camera(xyz=(0.2, 0.0, 0.4)) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = OPTICAL, xyz
    return out


def _detections(boxes, scores=None, depth=None) -> M.Detections:
    boxes = np.asarray(boxes, dtype=float).reshape(-1, 4)
    scores = np.ones(len(boxes)) if scores is None else np.asarray(scores, dtype=float)
    return M.Detections(scores=scores, labels=["person"] * len(boxes), boxes=boxes, image=depth)


# ------------------------------------------------------------------------------ transform tree
def test_quaternion_matrix_matches_yaw_and_rejects_zero():
    yaw = 0.7
    r = quaternion_matrix(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    np.testing.assert_allclose(r[:2, :2], [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]], atol=1e-12)
    with pytest.raises(ValueError, match="non-zero quaternion"):
        quaternion_matrix(0, 0, 0, 0)


def test_transform_tree_composes_chains_and_says_when_frames_are_not_connected():
    tree = TransformTree()
    tree.update(M.TFMessage(transforms=[
        _tf("odom", "base_link", (1.0, 2.0, 0.0), quaternion_matrix(0, 0, math.sin(0.25), math.cos(0.25))),
        _tf("base_link", "camera_link", (0.2, 0.0, 0.4), np.eye(3)),
        _tf("camera_link", "camera/depth", (0.0, 0.05, 0.0), OPTICAL),
    ]))
    m = tree.lookup("base_link", "camera/depth")
    np.testing.assert_allclose(m[:3, 3], [0.2, 0.05, 0.4], atol=1e-12)
    np.testing.assert_allclose(m[:3, :3], OPTICAL, atol=1e-12)
    # A point 2 m in front of the camera is 2.2 m ahead of the base, in the base frame.
    np.testing.assert_allclose((m @ [0, 0, 2.0, 1])[:3], [2.2, 0.05, 0.4], atol=1e-12)
    # Upwards in the tree (the inverse) and across a common ancestor.
    np.testing.assert_allclose(tree.lookup("camera/depth", "base_link"), np.linalg.inv(m), atol=1e-12)
    np.testing.assert_allclose(tree.lookup("odom", "camera_link")[:3, 3],
                               [1.0 + 0.2 * math.cos(0.5), 2.0 + 0.2 * math.sin(0.5), 0.4], atol=1e-12)
    assert tree.lookup("base_link", "elsewhere") is None
    problems = tree.update(M.TFMessage(transforms=[_tf("base_link", "bad", (math.nan, 0, 0), np.eye(3))]))
    assert problems and "'bad'" in problems[0] and "finite" in problems[0]
    with pytest.raises(ValueError, match="translation"):
        transform_matrix((1, 2), (0, 0, 0, 1))


# ------------------------------------------------------------------------------ analytic camera
def test_a_box_at_known_depth_becomes_the_point_it_shows():
    fx = fy = 200.0
    cx, cy = 159.5, 119.5
    k = CameraIntrinsics(fx, fy, cx, cy)
    # A target 3 m ahead of the camera and 0.5 m to its left, seen by a robot at (1, 2) facing +y.
    depth = np.full((240, 320), 10.0, np.float32)
    u = cx + (-0.5) * fx / 3.0  # left of the optical axis: smaller u
    v = cy
    depth[int(v) - 30:int(v) + 30, int(u) - 10:int(u) + 10] = 3.0
    box = [u - 12, v - 32, u + 12, v + 32]  # a detector's box is a bit larger than the object: the edges are background
    goal = pixel_goal_in_world(_detections([box]), depth, k, _base_from_camera(), np.array([1.0, 2.0, math.pi / 2]), WHERE)
    # In the base frame the target is at x = 0.2 + 3 (ahead), y = +0.5 (left); rotated by 90 deg.
    np.testing.assert_allclose(goal, [1.0 - 0.5, 2.0 + 3.2], atol=1e-6)


def test_the_best_detection_is_the_goal_and_points_of_interest_are_averaged():
    k = CameraIntrinsics(100.0, 100.0, 50.0, 50.0)
    depth = np.full((100, 100), 2.0, np.float32)
    depth[:, 60:] = 4.0
    base = _base_from_camera((0.0, 0.0, 0.0))
    pose = np.zeros(3)
    low, best = [10, 40, 30, 60], [70, 40, 90, 60]
    goal = pixel_goal_in_world(_detections([low, best], scores=[0.3, 0.9]), depth, k, base, pose, WHERE)
    np.testing.assert_allclose(goal, [4.0, -(80 - 50) * 4.0 / 100.0], atol=1e-9)
    points = M.PointsOfInterest(points=np.array([[40.0, 50.0], [60.0 - 1e-9, 50.0]]))  # both at 2 m depth
    goal = pixel_goal_in_world(points, depth, k, base, pose, "goal_point /points (PointsOfInterest)")
    np.testing.assert_allclose(goal, [2.0, -np.mean([-10.0, 10.0]) * 2.0 / 100.0], atol=1e-6)


# ------------------------------------------------------------------------------ real rendering
@pytest.fixture
def make_world():
    pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")
    from emos.actors.sim import SimClock, World

    worlds = []

    def factory(**kwargs):
        worlds.append(World(clock=SimClock(mode="lockstep"), **kwargs))
        return worlds[-1]

    yield factory
    for w in worlds:
        w.close()


def test_a_rendered_object_is_found_where_it_stands(make_world):
    """A pybullet camera on a robot that is turned and offset renders a thin red pole; its box
    (found in the picture) and the rendered depth, converted through the intrinsics of the
    camera's CameraInfo and the transform the simulator publishes, land on the pole."""
    pb = pytest.importorskip("pybullet")
    from emos.actors.sim import Camera, CameraConfig
    from emos.actors.sim.component.publishing import camera_mount
    from emos.actors.sim.msgs import camera_to_msgs

    world = make_world(ground=False)
    robot_pose = (1.0, -0.5, 0.4)
    robot = world.add_robot("jackal", robot_pose)
    cam = world.add_sensor(Camera(robot, CameraConfig(width=320, height=240, vfov_deg=60, mount_xyz=(0.25, 0.05, 0.45),
                                                      mount_pitch=0.1, frame_id="camera/depth")))
    target = (3.6, 1.0)
    radius = 0.04
    vis = world.client.createVisualShape(pb.GEOM_CYLINDER, radius=radius, length=1.2, rgbaColor=[1, 0, 0, 1])
    world.client.createMultiBody(baseMass=0, baseVisualShapeIndex=vis, basePosition=[target[0], target[1], 0.6])
    world.step()
    reading = cam.latest
    _, depth_msg, info = camera_to_msgs(reading)
    red = (reading.rgb[..., 0] > 150) & (reading.rgb[..., 1] < 90) & (reading.rgb[..., 2] < 90)
    rows, cols = np.nonzero(red)
    assert red.sum() > 50, "the pole is in view"
    box = [cols.min() - 2, rows.min() - 2, cols.max() + 2, rows.max() + 2]
    xyz, quat = camera_mount(cam)
    tree = TransformTree()
    tree.update(M.TFMessage(transforms=[_tf("base_link", "camera/depth", xyz, quaternion_matrix(*quat))]))
    base_from_camera = camera_on_base(tree, "base_link", depth_msg.header.frame_id, "tf /tf")
    depth = depth_in_metres(depth_msg, 1e-3, WHERE)
    goal = pixel_goal_in_world(_detections([box], depth=depth_msg), depth, intrinsics_of(info, "depth_camera_info"),
                               base_from_camera, np.array(robot_pose), WHERE)
    # The depth is the pole's front surface: within its radius (and a pixel) of its axis.
    assert math.dist(goal, target) < radius + 0.03, (goal, target)


# ------------------------------------------------------------------------------ bad inputs
def test_bad_pixel_goals_are_named():
    k = CameraIntrinsics(100.0, 100.0, 50.0, 50.0)
    depth = np.full((100, 100), 2.0)
    base, pose = _base_from_camera(), np.zeros(3)
    with pytest.raises(BadInput, match="holds no detection"):
        pixel_targets(_detections(np.zeros((0, 4))), WHERE)
    with pytest.raises(BadInput, match="x2 > x1"):
        pixel_targets(_detections([[30, 30, 10, 60]]), WHERE)
    with pytest.raises(BadInput, match="no finite point"):
        pixel_targets(M.PointsOfInterest(points=np.array([[np.nan, 1.0]])), "goal_point /p (PointsOfInterest)")
    nan_depth = depth.copy()
    nan_depth[40:60, 40:60] = np.nan
    with pytest.raises(BadInput, match=r"no valid depth .* around pixel \(50.0, 50.0\)"):
        pixel_goal_in_world(_detections([[40, 40, 60, 60]]), nan_depth, k, base, pose, WHERE)
    zero_depth = np.zeros_like(depth)
    with pytest.raises(BadInput, match="no valid depth"):
        pixel_goal_in_world(_detections([[40, 40, 60, 60]]), zero_depth, k, base, pose, WHERE)
    with pytest.raises(BadInput, match=r"outside the 100x100 depth image"):
        pixel_goal_in_world(_detections([[140, 40, 160, 60]]), depth, k, base, pose, WHERE)
    with pytest.raises(BadInput, match=re.escape(f"{WHERE}: the message carries no depth image")):
        depth_in_metres(None, 1e-3, WHERE)
    with pytest.raises(BadInput, match="'rgb8', not a depth image"):
        depth_in_metres(M.Image.from_numpy(np.zeros((4, 4, 3), np.uint8)), 1e-3, WHERE)
    mm = M.Image.from_numpy(np.full((4, 4), 1500, np.uint16), encoding="16UC1")
    np.testing.assert_allclose(depth_in_metres(mm, 1e-3, WHERE), 1.5)
    with pytest.raises(BadInput, match="no CameraInfo received yet"):
        intrinsics_of(None, "depth_camera_info /camera/info")
    with pytest.raises(BadInput, match="unusable camera intrinsics"):
        intrinsics_of(M.CameraInfo(), "depth_camera_info /camera/info")
    with pytest.raises(BadInput, match="no transform from 'base_link' to the camera frame 'cam'"):
        camera_on_base(TransformTree(), "base_link", "cam", "tf /tf")
    with pytest.raises(BadInput, match="no frame_id"):
        camera_on_base(TransformTree(), "base_link", "", "tf /tf")
    looped = TransformTree()
    looped.set("a", "b", np.eye(4))
    looped.set("b", "a", np.eye(4))
    with pytest.raises(BadInput, match="tf /tf: transform tree has a cycle"):
        camera_on_base(looped, "base_link", "a", "tf /tf")
