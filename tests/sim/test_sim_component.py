"""The Simulator component in a real supervised process: topics, rates, frames, commands."""
from __future__ import annotations

import time

import numpy as np
import pytest

from emos import msgs as M
from emos.transport.pubsub import Publisher, Subscriber
from tests.runtime.helpers import SystemUnderTest, kill_leftover_systems, wait_until

pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")

pytestmark = [pytest.mark.sim, pytest.mark.process]


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()


SIM_HEADER = """
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.nav.robot import RobotFrames
"""


class Recorder:
    """Subscribes to topics of a running system and keeps every message it takes."""

    def __init__(self, ctx, topics: dict[str, type]):
        self.subs = {name: Subscriber(ctx, name, cls, queue_size=500) for name, cls in topics.items()}
        self.got: dict[str, list] = {name: [] for name in topics}

    def poll(self) -> None:
        for name, sub in self.subs.items():
            self.got[name].extend(sub.take())

    def run(self, seconds: float, every: float = 0.02) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.poll()
            time.sleep(every)

    def dropped(self, name: str) -> int:
        """Messages the keep-last ring overwrote before this (possibly slow) reader took them."""
        return self.subs[name].dropped

    def close(self) -> None:
        for sub in self.subs.values():
            sub.close()


def _rate(msgs, dropped: int = 0) -> float:
    """Messages per second of simulated time, counting those a slow reader missed: a busy
    machine may stall the test's poll loop past the publisher's ring depth, which says nothing
    about the simulator's rate."""
    stamps = sorted({m.header.stamp.to_sec() for m in msgs})
    return (len(stamps) - 1 + dropped) / (stamps[-1] - stamps[0])


def test_simulator_publishes_sensors_at_their_rates_with_the_launcher_frames(tmp_path):
    system = SystemUnderTest(tmp_path, SIM_HEADER + """
sim = Simulator("sim", config=SimulatorConfig(world="house", robot="turtlebot3", odom_rate=50.0, scan_rate=10.0,
                                             camera_rate=5.0, camera_width=160, camera_height=120))
sim.outputs(camera=Topic(name="/image_raw/compressed", msg_type="CompressedImage"),
            rgbd=Topic(name="/camera/rgbd", msg_type="RGBD"),
            odom=Topic(name="/odometry/filtered", msg_type="Odometry"),
            map=Topic(name="/map", msg_type="OccupancyGrid"))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[sim])
launcher.frames = RobotFrames(world="map", odom="odom", scan="LDS-01")
launcher.bringup()
""").wait_up(components=["sim"], timeout=60)
    rec = Recorder(system.ctx, {"/odometry/filtered": M.Odometry, "/scan": M.LaserScan, "/tf": M.TFMessage,
                                "/clock": M.Clock, "/image_raw/compressed": M.CompressedImage, "/camera/rgbd": M.RGBD,
                                "/map": M.OccupancyGrid})
    try:
        wall0 = time.monotonic()
        rec.run(4.0)
        wall = time.monotonic() - wall0
    finally:
        rec.close()
        assert system.stop() == 0
    got = rec.got
    odom, scans, images, tfs = got["/odometry/filtered"], got["/scan"], got["/image_raw/compressed"], got["/tf"]
    assert len(odom) > 20 and len(scans) > 5 and len(images) > 3, {k: len(v) for k, v in got.items()}
    # Rates in simulated time are the configured ones (a missed message would lower them).
    assert _rate(odom, rec.dropped("/odometry/filtered")) == pytest.approx(50.0, rel=0.02)
    assert _rate(scans, rec.dropped("/scan")) == pytest.approx(10.0, rel=0.02)
    assert _rate(images, rec.dropped("/image_raw/compressed")) == pytest.approx(5.0, rel=0.05)
    # Realtime: simulated time never runs ahead of the wall clock (a busy machine slows it down,
    # which says nothing about the pacing: no lower bound).
    clock = [m.clock.to_sec() for m in got["/clock"]]
    assert 0 < clock[-1] - clock[0] <= 1.05 * wall
    # Frames: odometry odom -> base_link, the scan in the launcher's scan frame, the tree on /tf.
    assert (odom[-1].header.frame_id, odom[-1].child_frame_id) == ("odom", "base_link")
    assert odom[-1].pose.pose.position.x == pytest.approx(1.5) and odom[-1].pose.pose.position.y == pytest.approx(1.5)
    assert {s.header.frame_id for s in scans} == {"LDS-01"}
    assert len(scans[-1].ranges) == 360 and np.all(np.isfinite(scans[-1].ranges))
    edges = {(t.header.frame_id, t.child_frame_id) for t in tfs[-1].transforms}
    assert edges == {("map", "odom"), ("odom", "base_link"), ("base_link", "LDS-01"), ("base_link", "camera/rgb"),
                     ("base_link", "camera/depth")}
    lidar = next(t for t in tfs[-1].transforms if t.child_frame_id == "LDS-01")
    assert lidar.transform.translation.z == pytest.approx(0.2)  # the TurtleBot3's lidar height
    # The camera: JPEG frames that decode to the configured size; RGBD with metric depth.
    import io

    from PIL import Image

    frame = Image.open(io.BytesIO(images[-1].data.tobytes()))
    assert frame.format == "JPEG" and frame.size == (160, 120)
    assert images[-1].header.frame_id == "camera/rgb"
    rgbd = got["/camera/rgbd"][-1]
    depth = rgbd.depth.to_numpy()
    assert rgbd.depth.encoding == "32FC1" and depth.shape == (120, 160) and rgbd.depth.header.frame_id == "camera/depth"
    # Straight ahead (east) of the robot at (1.5, 1.5) is the bin at x = 3.8 - 0.3 m: ~2.1 m
    # from the camera (mounted 0.2 m ahead of the base).
    assert float(np.nanmin(depth[50:70, 75:85])) == pytest.approx(3.5 - 1.5 - 0.2, abs=0.15)
    # The map output is the shipped house map, the one a MapServer loads.
    from emos.actors.nav.maps import load_map
    from emos.actors.sim.data import HOUSE_MAP

    house = load_map(HOUSE_MAP)
    grid = got["/map"][0]
    assert grid.header.frame_id == "map" and grid.info.resolution == pytest.approx(0.05)
    assert (grid.info.width, grid.info.height) == (house.data.shape[1], house.data.shape[0])
    assert np.array_equal(grid.grid(), house.data)
    assert system.leftovers() == []


def test_twist_moves_the_robot_and_a_stale_command_stops_it(tmp_path):
    system = SystemUnderTest(tmp_path, SIM_HEADER + """
from emos.core import clock

class Probe(BaseComponent):
    def _execution_step(self):  # wall-timed, not use_sim_time: clock.now() follows /clock anyway
        with open(os.environ["PROBE"], "a") as f:
            f.write(f"{clock.now()!r} {clock.sim_time()!r}\\n")
        self.health_status.set_healthy()

probe = Probe("probe")
probe.config.loop_rate = 5.0
from emos.actors.sim import Box
sim = Simulator("sim", config=SimulatorConfig(world="empty", robot="jackal", command_timeout=0.3,
                                             obstacles=[Box((3.0, 0.0), (0.4, 2.0))]))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="TwistStamped"))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[sim, probe])
launcher.bringup()
""", env={"PROBE": str(tmp_path / "probe.txt")}).wait_up(components=["sim", "probe"], timeout=60)
    rec = Recorder(system.ctx, {"/odom": M.Odometry, "/scan": M.LaserScan})
    cmd = Publisher(system.ctx, "/cmd_vel", M.TwistStamped, publisher_id="test")

    def drive(vx: float, omega: float, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            cmd.publish(M.TwistStamped(twist=M.Twist(linear=M.Vector3(x=vx), angular=M.Vector3(z=omega))))
            rec.poll()
            time.sleep(0.05)

    def latest() -> M.Odometry:
        rec.poll()
        return rec.got["/odom"][-1]

    try:
        wait_until(lambda: rec.poll() or (rec.got["/odom"] and rec.got["/scan"]), 10, what="odometry and a scan")
        scan = rec.got["/scan"][0]
        ahead = scan.ranges[int(round(-scan.angle_min / scan.angle_increment))]
        assert ahead == pytest.approx(3.0 - 0.2, abs=0.02)  # the config's extra box, 2.8 m ahead
        drive(0.5, 0.0, 2.0)
        moving = latest()
        assert moving.twist.twist.linear.x == pytest.approx(0.5, abs=1e-6)
        assert moving.pose.pose.position.x > 0.5 and abs(moving.pose.pose.position.y) < 1e-6
        drive(0.0, 1.0, 1.0)
        turning = latest()
        assert turning.twist.twist.angular.z == pytest.approx(1.0, abs=1e-6)
        assert turning.pose.pose.orientation.yaw() > 0.5
        # Silence: within command_timeout (+ braking) the robot stands still, and stays.
        time.sleep(1.0)
        stopped = latest()
        assert stopped.twist.twist.linear.x == 0.0 and stopped.twist.twist.angular.z == 0.0
        time.sleep(0.5)
        after = latest()
        assert after.pose.pose.position.x == stopped.pose.pose.position.x
        assert after.pose.pose.orientation.yaw() == stopped.pose.pose.orientation.yaw()
        sim_now = after.header.stamp.to_sec()
    finally:
        cmd.close()
        rec.close()
        assert system.stop() == 0
    # A component that reads emos.core.clock.now() gets simulated time once the Simulator runs
    # (it started at 0 with the simulator, so it is far below the wall clock's epoch seconds).
    probes = [line.split() for line in (tmp_path / "probe.txt").read_text().splitlines()]
    late = [(float(now), sim) for now, sim in probes if sim != "None"]
    assert late and all(0.0 <= now <= sim_now + 2.0 for now, _ in late)
    assert all(0.0 <= float(sim) - now < 0.5 for now, sim in late)  # sim_time() read just after now()


def test_realistic_simulator_dynabarn_jackal_laser_wheel_imu_odometry(tmp_path):
    """The realistic options end to end: DynaBARN world (obstacles move in simulated time),
    the skid-steer Jackal, its 720-beam laser at 50 Hz and wheel + IMU odometry."""
    system = SystemUnderTest(tmp_path, SIM_HEADER + """
sim = Simulator("sim", config=SimulatorConfig(world="dynabarn:0", robot="jackal-barn", odometry_mode="wheel-imu",
                                             scan_preset="jackal"))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[sim])
launcher.bringup()
""").wait_up(components=["sim"], timeout=60)
    rec = Recorder(system.ctx, {"/odom": M.Odometry, "/scan": M.LaserScan})
    cmd = Publisher(system.ctx, "/cmd_vel", M.Twist, publisher_id="test")
    try:
        rec.run(2.0)
        scans = rec.got["/scan"]
        assert len(scans) > 20 and len(scans[0].ranges) == 720
        assert scans[0].angle_min == pytest.approx(-2.35619, abs=1e-5)
        assert _rate(scans, rec.dropped("/scan")) == pytest.approx(50.0, rel=0.05)
        # Standing still, the scan changes: the crossing cylinders move.
        first, last = np.asarray(scans[0].ranges), np.asarray(scans[-1].ranges)
        both = np.isfinite(first) & np.isfinite(last)
        assert np.abs(first[both] - last[both]).max() > 0.05
        end = time.monotonic() + 1.5
        while time.monotonic() < end:
            cmd.publish(M.Twist(linear=M.Vector3(x=0.5)))
            rec.run(0.05)
        moving = rec.got["/odom"][-1]
        assert moving.twist.twist.linear.x > 0.3 and moving.pose.pose.position.x > 0.2
        rec.run(1.0)  # silence: the 0.25 s watchdog stops the base
        stopped = rec.got["/odom"][-1]
        assert abs(stopped.twist.twist.linear.x) < 0.05  # wheel speed with its noise, ~0
    finally:
        cmd.close()
        rec.close()
        assert system.stop() == 0
