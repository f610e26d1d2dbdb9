import math

import numpy as np
import pytest

from emos.actors.sim import Camera, CameraConfig

pytestmark = pytest.mark.sim


def _red_sphere(world, xyz, radius=0.05):
    pb = pytest.importorskip("pybullet")
    vis = world.client.createVisualShape(pb.GEOM_SPHERE, radius=radius, rgbaColor=[1, 0, 0, 1])
    world.client.createMultiBody(baseMass=0, baseVisualShapeIndex=vis, basePosition=list(xyz))


def test_intrinsics_follow_the_field_of_view():
    cfg = CameraConfig(width=320, height=240, vfov_deg=60)
    k = cfg.intrinsics()
    f = 120 / math.tan(math.radians(30))
    np.testing.assert_allclose(k, [[f, 0, 159.5], [0, f, 119.5], [0, 0, 1]])


def test_camera_round_trip_projects_a_known_point_where_it_renders(make_world):
    world = make_world(ground=False)
    robot = world.add_robot("jackal", (0.0, 0.0, 0.0))
    cam = world.add_sensor(Camera(robot, CameraConfig(width=320, height=240, vfov_deg=60, mount_xyz=(0.2, 0.0, 0.4))))
    target = np.array([3.0, 0.5, 0.6])
    _red_sphere(world, target)
    world.step()
    reading = cam.latest
    # Optical frame of a camera at (0.2, 0, 0.4) looking along +x: x right (-y), y down (-z), z forward.
    p_cam = reading.rotation.T @ (target - reading.position)
    np.testing.assert_allclose(p_cam, [-0.5, -0.2, 2.8], atol=1e-9)
    u, v, w = reading.k @ p_cam
    u, v = u / w, v / w
    rgb = reading.rgb.astype(int)
    red = (rgb[..., 0] > 150) & (rgb[..., 1] < 90) & (rgb[..., 2] < 90)
    assert red.sum() > 10
    rows, cols = np.nonzero(red)
    assert cols.mean() == pytest.approx(u, abs=1.0)
    assert rows.mean() == pytest.approx(v, abs=1.0)
    # Depth at the blob centre is the sphere's front surface along the optical axis.
    z = reading.depth[int(round(v)), int(round(u))]
    assert z == pytest.approx(2.8 - 0.05, abs=0.02)
    # Back-projecting the blob's pixels lands on the sphere's surface in the world.
    cloud = reading.point_cloud(world_frame=True)
    near = cloud[np.linalg.norm(cloud - target, axis=1) < 0.2]
    assert len(near) == pytest.approx(red.sum(), rel=0.3)
    np.testing.assert_allclose(np.linalg.norm(near - target, axis=1), 0.05, atol=0.02)


def test_depth_is_infinite_where_nothing_is_seen_and_cloud_skips_it(make_world):
    world = make_world(ground=False)
    robot = world.add_robot("jackal", (0.0, 0.0, 0.0))
    cam = world.add_sensor(Camera(robot, CameraConfig(width=64, height=48)))
    world.step()
    assert np.all(np.isinf(cam.latest.depth))
    assert cam.latest.point_cloud().shape == (0, 3)


def test_camera_sees_a_wall_at_the_right_depth_everywhere(make_world):
    world = make_world(ground=False)
    world.add_wall((4.0, -20.0), (4.0, 20.0), thickness=0.2, height=5.0)  # face at x = 3.9
    robot = world.add_robot("jackal", (0.0, 0.0, 0.0))
    cam = world.add_sensor(Camera(robot, CameraConfig(width=80, height=60, mount_xyz=(0.0, 0.0, 2.5))))
    world.step()
    depth = cam.latest.depth
    np.testing.assert_allclose(depth, 3.9, atol=0.02)  # a plane facing the camera: constant z
    cloud = cam.latest.point_cloud(world_frame=True)
    np.testing.assert_allclose(cloud[:, 0], 3.9, atol=0.02)


@pytest.mark.parametrize("kwargs", [dict(width=0), dict(vfov_deg=180), dict(near=1, far=0.5), dict(mount_pitch=2.0)])
def test_camera_config_rejects_bad_values(kwargs):
    with pytest.raises(ValueError, match="CameraConfig"):
        CameraConfig(**kwargs)
