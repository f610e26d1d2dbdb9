"""Issue 35 item 6: a robot whose only interface is ROS 2, both ways.

* EMOS's navigation stack (recipes/point_navigation_ros2.py, no Simulator) drives the plain rclpy
  robot of recipes/ros2/diff_drive_robot.py (a differential base, a lidar ray-cast in the arena's
  map) to two goals through the bridge: /odom and /scan from ROS 2, /cmd_vel to it. The goals are
  shorter than the recipe's defaults (about 4.5 m of driving instead of 9) to keep the test's time
  near 40 s on this machine; the robot judges collisions itself, against the map.
* The reverse: ``emos run --ros2`` on a recipe with the Simulator, and an rclpy teleop node drives
  it; the Simulator's odometry, as an rclpy listener sees it, moves.
"""
from __future__ import annotations

import json
import math
import signal
import subprocess

import pytest

from tests.ros2.conftest import REPO, Peer, fastdds_files, fastdds_names, free_domains
from tests.runtime.helpers import HANG_S, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

ROBOT = REPO / "recipes" / "ros2" / "diff_drive_robot.py"
RECIPE = REPO / "recipes" / "point_navigation_ros2.py"
GOALS = [(0.5, -1.6), (-0.5, 1.0)]  # beside the table, then past it up the room


def _no_new_fastdds_files(before: set[str]) -> None:
    """No Fast DDS file that no live process uses, beyond those there before the test (another
    test's node beside this one may be starting or stopping: its files are gone or in use a
    moment later; a leak stays)."""
    wait_until(lambda: not (fastdds_files() - before), timeout=10.0, what=f"no Fast DDS file left behind: {fastdds_files() - before}")


def _run_recipe_body(path) -> str:
    # SystemUnderTest runs a recipe text; this one runs the shipped recipe file as __main__.
    return f"import runpy\nrunpy.run_path({str(path)!r}, run_name='__main__')\n"


def test_emos_navigation_drives_the_ros2_robot_to_both_goals(tmp_path):
    (domain,) = free_domains(1)
    fastdds_before = fastdds_names()
    robot = Peer(str(ROBOT), "--domain", domain)
    robot.wait_for(lambda line: line.startswith("ready"), what="the robot ready")
    out_dir = tmp_path / "out"
    system = SystemUnderTest(tmp_path, _run_recipe_body(RECIPE),
                             env={"EMOS_NAV_OUT": str(out_dir), "EMOS_NAV_GOALS": ";".join(f"{x},{y}" for x, y in GOALS),
                                  "EMOS_NAV_TIMEOUT": str(2 * HANG_S)},
                             args=["--ros2", "--ros2-topics", "/odom,/scan,/cmd_vel", "--ros-domain-id", str(domain)])
    try:
        code = system.wait_exit(timeout=4 * HANG_S)  # bounds a hang; the Mission's own limit is 2 * HANG_S
    except subprocess.TimeoutExpired:
        system.kill_all()
        raise AssertionError("the navigation run did not end:\n" + system.output()[-4000:]) from None
    output = system.output()
    assert code == 0, output[-4000:]
    summary = json.loads((out_dir / "summary.json").read_text())
    assert summary["reached"] == [True, True], summary

    # Signalled here, not through Peer.stop(): that waits (up to HANG_S) for a line that is exactly
    # "ready" so as not to signal a peer still starting rclpy, and this robot says "ready: domain ...";
    # it said so above, so it is past its start and the wait only cost a minute per run.
    robot.proc.send_signal(signal.SIGTERM)
    line = robot.wait_for(lambda text: text.startswith("summary "), what="the robot's summary")
    driven = json.loads(line.split(" ", 1)[1])
    assert driven["collisions"] == 0, robot.lines[-20:]
    assert driven["cmds"] > 0 and driven["path_m"] > 3.0, driven
    assert math.dist((driven["x"], driven["y"]), GOALS[-1]) < 0.35, driven  # where the robot itself says it is
    assert not system.leftovers()
    _no_new_fastdds_files(fastdds_before)


SIM_RECIPE = """
from emos.actors.sim import Simulator, SimulatorConfig
from emos.packages import get_package_share_directory

world = os.path.join(get_package_share_directory("kompass_sim"), "maps", "turtlebot3_webots.yaml")
sim = Simulator("sim", config=SimulatorConfig(world=world, spawn=(0.0, 0.0, 0.0)))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=Topic(name="/odom", msg_type="Odometry"))
launcher = Launcher()
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
launcher.bringup()
"""


def test_an_rclpy_teleop_drives_the_emos_simulator(tmp_path):
    (domain,) = free_domains(1)
    fastdds_before = fastdds_names()
    system = SystemUnderTest(tmp_path, SIM_RECIPE, args=["--ros2", "--ros2-topics", "/cmd_vel,/odom", "--ros-domain-id", str(domain)])
    teleop = None
    try:
        system.wait_up(components=["sim", "ros2_bridge"])
        teleop = Peer("teleop.py", domain, 0.2, 0.0)  # 0.2 m/s ahead: the table is 0.85 m away
        first = teleop.wait_for(lambda line: line.startswith("odom "), what="the Simulator's odometry")
        x0 = float(first.split()[1])
        teleop.wait_for(lambda line: line.startswith("odom ") and float(line.split()[1]) > x0 + 0.15,
                        what="odometry 0.15 m ahead of where it started")
    finally:
        if teleop is not None:
            teleop.stop()
        assert system.stop() == 0, system.output()[-3000:]
    assert not system.leftovers()
    _no_new_fastdds_files(fastdds_before)
