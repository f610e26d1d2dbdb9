"""Kilted: EMOS on ROS 2 Kilted's wheels (rclpy 9) talks to Jazzy nodes (rclpy 7) and back.

The Kilted wheels cannot share one environment with the Jazzy ones the rest of the suite uses
(both install `ros-rclpy`), so `scripts/setup.sh --test` puts them in a venv of their own that
sees this Python's packages (``--system-site-packages``: EMOS and numpy come from here, rclpy
and the ROS 2 libraries from the venv). The EMOS run uses that venv's interpreter; the rclpy
peers use this one (Jazzy): one Fast DDS wire, two distributions.
"""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from tests.ros2.conftest import Peer, fastdds_files, fastdds_names, free_domains
from tests.runtime.helpers import HANG_S, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

VENV = Path(os.environ.get("EMOS_ROS2_KILTED_VENV", Path.home() / ".cache" / "emos" / "ros2-kilted"))
KILTED_PYTHON = VENV / "bin" / "python"

RECIPE = """
from emos.actors.ros2 import Ros2BridgeComponent, Ros2BridgeConfig


class Talker(BaseComponent):
    def custom_on_activate(self):
        self.n = 0
    def _execution_step(self):
        self.n += 1
        self.publish("k_out", M.String(data=f"kilted{{self.n}}"))
        self.health_status.set_healthy()


class Listener(BaseComponent):
    def custom_on_activate(self):
        self.last = None
    def _execution_step(self):
        m = self.get_input("k_in")
        if m is not None and m.data != self.last:
            self.last = m.data
            print("EMOS got", m.data, flush=True)
        self.health_status.set_healthy()


talker = Talker(component_name="talker", outputs=[Topic(name="k_out", msg_type="String")])
talker.config.loop_rate = 5.0
listener = Listener(component_name="listener", inputs=[Topic(name="k_in", msg_type="String")])
listener.config.loop_rate = 20.0
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[talker, listener])
launcher.add_pkg(components=[Ros2BridgeComponent(config=Ros2BridgeConfig(topics=["/k_out", "/k_in"], domain_id={domain}))],
                 package_name="ros2", multiprocessing=True)
launcher.bringup()
"""


def test_emos_on_kilted_exchanges_topics_with_jazzy_nodes_both_ways(tmp_path):
    assert KILTED_PYTHON.exists(), (f"no Kilted venv at {VENV}: scripts/setup.sh --test makes it "
                                    "(or set EMOS_ROS2_KILTED_VENV to one with the ros-kilted-* wheels)")
    said = subprocess.run([str(KILTED_PYTHON), "-m", "emos", "version"], capture_output=True, text=True, timeout=HANG_S)
    assert "ROS 2 kilted (rclpy 9." in said.stdout, said.stdout + said.stderr
    (domain,) = free_domains(1)
    shm_before = fastdds_names()
    system = SystemUnderTest(tmp_path, RECIPE.format(domain=domain), duration=300, python=str(KILTED_PYTHON)).wait_up()
    try:
        hears = Peer("listener.py", domain, "/k_out", "std_msgs/msg/String", "default")
        speaks = Peer("talker.py", domain, "/k_in", "std_msgs/msg/String", 5, "default", "--prefix", "jazzy")
        hears.wait_for(lambda line: line.startswith("got kilted"), what="a message from EMOS on Kilted")
        wait_until(lambda: "EMOS got jazzy" in system.output(), HANG_S, what="a Jazzy talker's message inside EMOS")
        speaks.stop(), hears.stop()
        assert "ROS 2 kilted (rclpy 9." in system.output()  # the bridge says which ROS 2 it holds
    finally:
        assert system.stop() == 0, system.output()[-3000:]
    assert fastdds_files() <= shm_before  # nothing of the run's Fast DDS left behind
