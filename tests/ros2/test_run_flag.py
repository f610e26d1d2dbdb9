"""``emos run --ros2``: the Launcher adds the bridge itself (through its entry point), and a plain
rclpy node on the chosen domain receives the recipe's scans; `emos topic list` marks what the
bridge carries."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.ros2.conftest import Peer, free_domains
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process

RECIPE = """
class Lidar(BaseComponent):
    def _execution_step(self):
        self.publish("/scan", M.LaserScan(header=M.Header(frame_id="lidar"), ranges=np.full(8, 2.0, dtype=np.float32)))
        self.health_status.set_healthy()

lidar = Lidar(component_name="lidar", outputs=[Topic(name="/scan", msg_type="LaserScan")])
lidar.config.loop_rate = 10.0
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[lidar])
launcher.bringup()
"""


def test_emos_run_with_ros2_bridges_the_recipes_topics_to_a_ros2_node(tmp_path):
    (domain,) = free_domains(1)
    system = SystemUnderTest(tmp_path, RECIPE, args=["--ros2", "--ros-domain-id", str(domain)])
    listener = None
    try:
        system.wait_up(components=["lidar", "ros2_bridge"])
        assert "emos run: bridging to ROS 2 jazzy" in system.output()
        listener = Peer("listener.py", domain, "/scan", "sensor_msgs/msg/LaserScan", "default")
        listener.wait_for(lambda line: line.startswith("got lidar"), what="a scan from the EMOS run")
        assert system.ctx is not None
        out = wait_until(lambda: (r := subprocess.run([sys.executable, "-m", "emos", "topic", "list", "--json", "--run", system.ctx.run_id],
                                                     capture_output=True, text=True, timeout=120)).returncode == 0
                         and "ros2" in json.loads(r.stdout).get("/scan", {}) and r, what="/scan marked as bridged")
        assert json.loads(out.stdout)["/scan"]["ros2"] == {"direction": "emos->ros2", "type": "sensor_msgs/msg/LaserScan"}
    finally:
        if listener is not None:
            listener.stop()
        assert system.stop() == 0
