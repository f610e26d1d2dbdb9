"""``Topic(..., transport="ros2")``: a component's topics on the ROS 2 graph from its own process
(emos.interop.ros2.direct), against real rclpy peers.

One run (module fixture): a component publishing on and subscribing to ``ros2`` topics, beside the
run's ROS 2 bridge on the same domain; its Fast DDS uses shared memory (``$EMOS_ROS2_FASTDDS=shm``),
so that a SIGKILLed component has Fast DDS files to leave behind. The peers talk UDP only
(tests/ros2/conftest.Peer): every Fast DDS file here is the component's."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys

import pytest

from emos.transport.context import encode_name
from tests.ros2.conftest import _PEERS, REPO, Peer, fastdds_files, fastdds_names, free_domains
from tests.runtime.helpers import HANG_S, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

SCAN = "sensor_msgs/msg/LaserScan"

RECIPE = """
import sys
sys.path.insert(0, {repo!r})
from emos.actors.ros2 import Ros2BridgeComponent, Ros2BridgeConfig
from emos.interop.ros2_cdr import codec_for
from tests.ros2.samples import sample

CDR = codec_for("jazzy")
SCAN = {scan!r}


def say(*words):
    sys.stdout.write(" ".join(map(str, words)) + "\\n")
    sys.stdout.flush()


class Direct(BaseComponent):
    # Publishes a String and a full LaserScan on ros2 topics; an rclpy relay sends them back on
    # other ros2 topics, which it reads; it also reads a talker that sends garbage now and then.
    def custom_on_activate(self):
        self.seq = 0
        self.scan = sample(SCAN)
        self.last = {{}}

    def _execution_step(self):
        self.seq += 1
        self.publish("/direct/out", M.String(data=f"e{{os.getpid()}}-{{self.seq}}"))
        self.publish("/direct/scan", self.scan)
        back = self.get_input("/direct/in")
        if back is not None and back.data != self.last.get("in"):
            self.last["in"] = back.data
            say("EMOS in", back.data, "pid", os.getpid())
        scan = self.get_input("/direct/scan_back")
        if scan is not None and "scan" not in self.last:
            self.last["scan"] = True
            say("EMOS scan back", "equal" if CDR.serialize(scan) == CDR.serialize(self.scan) else "DIFFERENT")
        g = self.get_input("/direct/garbage")
        if g is not None and g.data != self.last.get("g"):
            self.last["g"] = g.data
            say("EMOS garbage", g.data)
        self.health_status.set_healthy()


R = "ros2"
direct = Direct(component_name="direct",
                inputs=[Topic(name="/direct/in", msg_type="String", transport=R), Topic(name="/direct/scan_back", msg_type=SCAN, transport=R),
                        Topic(name="/direct/garbage", msg_type="String", transport=R)],
                outputs=[Topic(name="/direct/out", msg_type="String", transport=R), Topic(name="/direct/scan", msg_type=SCAN, transport=R)])
direct.config.loop_rate = 20.0
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[direct])
launcher.add_pkg(components=[Ros2BridgeComponent(config=Ros2BridgeConfig(domain_id={domain}))], package_name="ros2", multiprocessing=True)
launcher.bringup()
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ros2direct")
    (domain,) = free_domains(1)
    shm_before = fastdds_names()
    system = SystemUnderTest(tmp, RECIPE.format(repo=str(REPO), scan=SCAN, domain=domain),
                             env={"EMOS_ROS2_DOMAIN_ID": str(domain), "EMOS_ROS2_FASTDDS": "shm"})
    system.domain = domain
    relay = None
    try:
        system.wait_up(components=["direct", "ros2_bridge"])
        # The rclpy node the component talks with, for the whole module (conftest stops a test's
        # own peers after it).
        relay = Peer("relay.py", domain, "/direct/out:/direct/in:std_msgs/msg/String", f"/direct/scan:/direct/scan_back:{SCAN}")
        _PEERS.remove(relay)
        relay.wait_for(lambda line: line == "ready", what="ready")
        yield system
    finally:
        if relay is not None:
            relay.stop()
        code = system.stop()
        print(system.output()[-3000:])
    assert code == 0
    assert system.leftovers() == []
    # The component closed its participant on stop: none of its Fast DDS files is left (a file of
    # a node that is stopping is released a moment later; a leak stays).
    wait_until(lambda: not (fastdds_files() - shm_before), timeout=10.0, what=f"no Fast DDS file left: {fastdds_files() - shm_before}")


def test_component_and_rclpy_node_exchange_messages_with_fields_equal(run):
    wait_until(lambda: re.search(r"EMOS in e\d+-\d+ pid", run.output()), what="the component's String back through the rclpy relay")
    wait_until(lambda: "EMOS scan back" in run.output(), what="the LaserScan back through the rclpy relay")
    assert "EMOS scan back equal" in run.output()
    # The component's node is on the graph under its own name; the bridge did not bridge its topics.
    wait_until(lambda: re.search(r"ROS 2: node /direct on domain \d+ in this process", run.output()), what="the component's node")


def test_a_malformed_cdr_sample_is_dropped_with_one_line_and_the_stream_goes_on(run):
    talker = Peer("talker.py", run.domain, "/direct/garbage", "std_msgs/msg/String", 20, "default", "--prefix", "g", "--garbage-every", 3)
    talker.wait_for(lambda line: line == "ready", what="ready")
    bad = r"ROS 2 topic /direct/garbage: a malformed std_msgs/msg/String sample"
    wait_until(lambda: re.search(bad, run.output()), what="the malformed-sample line")
    first = max(int(m) for m in re.findall(r"EMOS garbage g(\d+)", run.output()) or ["-1"])
    wait_until(lambda: any(int(m) > first + 6 for m in re.findall(r"EMOS garbage g(\d+)", run.output())), what="good samples after the bad ones")
    # Rate-limited (one line per 10 s, each with the count so far): fewer lines than bad samples.
    counts = [int(n) for n in re.findall(bad + r" \(\d+ bytes\) dropped \((\d+) so far\)", run.output())]
    assert counts and (len(counts) == 1 or counts[-1] > len(counts)), counts
    assert run.state("direct") == "active"


def test_the_bridge_does_not_bridge_a_topic_the_component_carries(run):
    # The relay publishes /direct/in and /direct/scan_back, the component /direct/out and /direct/scan:
    # each has a ROS 2 publisher other than the bridge, which the bridge would bring into EMOS.
    for topic in ("/direct/out", "/direct/in", "/direct/scan", "/direct/scan_back"):
        said = wait_until(lambda topic=topic: re.search(rf"ROS 2 bridge: {topic} (not bridged: .*|\(\S+\) ROS 2 -> EMOS.*)", run.output()),
                          what=f"the bridge's word on {topic}").group(0)
        assert said.startswith(f"ROS 2 bridge: {topic} not bridged: a component carries it on the ROS 2 graph itself"), said
    path = run.run_dir / "ros2_bridge.json"  # written once the bridge bridges something
    bridged = json.loads(path.read_text())["topics"] if path.exists() else {}
    assert not [t for t in bridged if t.startswith("/direct/")], bridged
    # `emos topic list` shows them all the same, as carried on the ROS 2 graph by the component.
    listed = subprocess.run([sys.executable, "-m", "emos", "topic", "list", "--json", "--run", run.ctx.run_id],
                            capture_output=True, text=True, timeout=HANG_S)
    assert listed.returncode == 0, listed.stderr[-2000:]
    topics = json.loads(listed.stdout)
    assert topics["/direct/out"]["transport"] == "ros2" and topics["/direct/out"]["publishers"] == ["direct"], topics.get("/direct/out")
    assert topics["/direct/scan"]["ros2"] == {"direction": "direct", "type": "sensor_msgs/msg/LaserScan"}, topics.get("/direct/scan")
    assert topics["/direct/in"]["subscribers"] == 1 and topics["/direct/in"]["publishers"] == [], topics.get("/direct/in")
    # No EMOS ring was made for them either (the bridge's way ROS 2 -> EMOS).
    carried = [f".{encode_name(t)}." for t in ("/direct/out", "/direct/in", "/direct/scan", "/direct/scan_back", "/direct/garbage")]
    assert not [n for n in os.listdir("/dev/shm") if n.startswith(run.ctx.shm_prefix) and any(c in n[len(run.ctx.shm_prefix) - 1:] for c in carried)]


def _dds_files_of(pid: int) -> set[str]:
    with open(f"/proc/{pid}/maps") as f:
        return {line.rsplit("/", 1)[-1].strip() for line in f if "/dev/shm/" in line and ("fastrtps" in line or "fastdds" in line)}


def test_the_component_sigkilled_is_restarted_resumes_and_leaves_no_dds_files(run):
    pid = run.pid("direct")
    wait_until(lambda: f"pid {pid}" in run.output(), what="the stream before the kill")
    mapped = _dds_files_of(pid)
    assert mapped, "the component's Fast DDS uses shared memory in this test"
    os.kill(pid, signal.SIGKILL)
    new = run.wait_new_pid("direct", pid)
    wait_until(lambda: re.search(rf"EMOS in e{new}-\d+ pid {new}", run.output()), what="the stream after the restart")
    # The restarted participant removed what the killed one left (the files nobody holds now).
    wait_until(lambda: not (fastdds_files() & mapped), what=f"the killed component's Fast DDS files removed: {mapped}")


def test_without_ros2_declaring_a_ros2_topic_fails_at_definition_with_the_install_hint(tmp_path):
    script = """
import importlib.abc, sys
class NoRos(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name == "rclpy" or name.startswith("rclpy."):
            raise ImportError("hidden by the test: no ROS 2 here")
        return None
sys.meta_path.insert(0, NoRos())
from emos import Topic
from emos.interop.ros2 import env
try:
    Topic(name="scan", msg_type="LaserScan", transport="ros2")
except env.Ros2Unavailable as exc:
    print("REFUSED", exc)
else:
    print("ACCEPTED")
"""
    environ = {k: v for k, v in os.environ.items() if k not in ("AMENT_PREFIX_PATH", "ROS_DISTRO")}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=HANG_S, env=environ, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    line = out.stdout.strip()
    assert line.startswith("REFUSED Topic '/scan' (transport='ros2'): ROS 2 is not available"), line
    assert "pip install 'emos[ros2]'" in line and "\n" not in line
