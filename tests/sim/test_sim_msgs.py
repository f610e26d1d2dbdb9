import numpy as np
import pytest

pytestmark = pytest.mark.sim

msgs = pytest.importorskip("emos.msgs", reason="emos.msgs (runtime) is not importable")

from emos.actors.sim import Camera, CameraConfig, Lidar, LidarConfig, Odometry, Wall  # noqa: E402
from emos.actors.sim.msgs import cloud_to_msg  # noqa: E402


def test_readings_convert_to_ros_shaped_messages(make_world):
    world = make_world(ground=False)
    world.add(Wall((3.0, -5.0), (3.0, 5.0), thickness=0.2, height=3.0))
    robot = world.add_robot("jackal", (0.0, 0.0, 0.0))
    lidar = world.add_sensor(Lidar(robot, LidarConfig(fov_deg=90, beams=91)))
    cam = world.add_sensor(Camera(robot, CameraConfig(width=40, height=30)))
    odom = world.add_sensor(Odometry(robot))
    robot.command(0.5, 0.0, 0.1)
    world.step(101)

    scan = lidar.latest.to_msg()
    assert isinstance(scan, msgs.LaserScan)
    assert scan.header.frame_id == "laser"
    assert scan.header.stamp.sec == 1 and scan.header.stamp.nanosec == pytest.approx(10_000_000, abs=1)
    assert scan.ranges.dtype == np.float32 and len(scan.ranges) == 91
    np.testing.assert_array_equal(scan.ranges, lidar.latest.ranges)
    assert scan.angle_increment == pytest.approx(np.radians(1.0))

    rgb, depth, info = cam.latest.to_msgs()
    np.testing.assert_array_equal(rgb.to_numpy(), cam.latest.rgb)
    np.testing.assert_array_equal(depth.to_numpy(), cam.latest.depth)
    assert depth.encoding == "32FC1"
    np.testing.assert_allclose(info.k.reshape(3, 3), cam.latest.k)
    assert (info.width, info.height) == (40, 30)
    cloud = cloud_to_msg(cam.latest)
    np.testing.assert_allclose(cloud.xyz(), cam.latest.point_cloud())

    o = odom.latest.to_msg()
    assert isinstance(o, msgs.Odometry)
    assert o.child_frame_id == "base_link"
    assert o.pose.pose.position.x == pytest.approx(robot.pose[0])
    assert o.pose.pose.orientation.yaw() == pytest.approx(robot.pose[2])
    assert o.twist.twist.linear.x == pytest.approx(0.5)
    assert o.twist.twist.angular.z == pytest.approx(0.1)
    back = msgs.unpack(msgs.Odometry, msgs.pack(o))  # survives the topic codec
    assert back.pose.pose.position.x == pytest.approx(robot.pose[0])
    np.testing.assert_array_equal(msgs.unpack(msgs.LaserScan, msgs.pack(scan)).ranges, scan.ranges)
