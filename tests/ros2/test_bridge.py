"""The ROS 2 bridge against real rclpy nodes: topics both ways, QoS, bad input, faults.

One EMOS run (module fixture) with the bridge on a random domain, and rclpy peers started and
stopped by each test."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time

import pytest

from tests.ros2.conftest import _PEERS, REPO, Peer, fastdds_files, fastdds_names, free_domains
from tests.ros2.samples import shared_types_with_rclpy, topic_of
from tests.runtime.helpers import HANG_S, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

TYPES = sorted(shared_types_with_rclpy())

RECIPE = """
import sys, zlib
sys.path.insert(0, {repo!r})
from emos.config.qos import QoSConfig, TRANSIENT_LOCAL
from emos.msgs import Header, Image, LaserScan, Time, String, OccupancyGrid
from emos.msgs.geometry import TFMessage, TransformStamped
from emos.interop.ros2_cdr import codec_for
from emos.actors.ros2 import Ros2BridgeComponent, Ros2BridgeConfig
from tests.ros2.samples import sample, topic_of

TYPES = {types!r}
CAM_ON = {cam_on!r}
CALL_ON = CAM_ON + ".call"
CDR = codec_for("jazzy")


def say(*words):
    # One write, newline included: the run is unbuffered (PYTHONUNBUFFERED), where print writes
    # the text and its newline apart and another process's log line can land between them
    # (seen: "RT geometry_msgs/msg/TransformStamped equal2026-11-30 ... INFO ...").
    sys.stdout.write(" ".join(map(str, words)) + "\\n")
    sys.stdout.flush()


class RoundTrip(BaseComponent):
    # Publishes one sample of every shared type until its copy comes back through a ROS 2 relay.
    def custom_on_activate(self):
        self.samples = {{t: sample(t) for t in TYPES}}
        self.done = set()

    def _execution_step(self):
        for t, msg in self.samples.items():
            if t in self.done:
                continue
            back = self.get_input(topic_of(t) + "/back")
            if back is not None:
                same = CDR.serialize(back) == CDR.serialize(msg)
                say("RT", t, "equal" if same else "DIFFERENT")
                self.done.add(t)
            else:
                self.publish(topic_of(t), msg)
        self.health_status.set_healthy()


class Sensors(BaseComponent):
    def custom_on_activate(self):
        self.seq = 0
        self.cam = 0
        grid = OccupancyGrid(header=Header(stamp=Time.now(), frame_id="map1"))
        grid.info.width, grid.info.height, grid.info.resolution = 4, 3, 0.05
        grid.data = np.arange(12, dtype=np.int8)
        self.publish("map", grid)  # once, before any ROS 2 node asks: a latched topic

    def _execution_step(self):
        self.seq += 1
        if self.seq % 3 == 0:
            self.publish("scan", LaserScan(header=Header(stamp=Time.now(), frame_id=f"s{{self.seq}}"), ranges=np.ones(90, np.float32)))
            self.publish("clash", String(data="emos"))
            tf = TransformStamped(header=Header(frame_id="odom"), child_frame_id="base_link")
            self.publish("tf", TFMessage(transforms=[tf]))
        if os.path.exists(CAM_ON):
            pixels = np.full((480, 640, 3), self.cam % 251, np.uint8)
            pixels[self.cam % 480, :, 0] = 7
            crc = zlib.crc32(pixels.data) & 0xFFFFFFFF
            self.publish("camera/image", Image.from_numpy(pixels, "rgb8", header=Header(stamp=Time.now(), frame_id=f"{{self.cam}}:{{crc}}")))
            self.cam += 1
        self.health_status.set_healthy()


class Listener(BaseComponent):
    def custom_on_activate(self):
        self.last = {{}}

    def _execution_step(self):
        for name in ("chatter", "ros_map"):
            m = self.get_input(name)
            key = None if m is None else (m.data if name == "chatter" else m.header.frame_id)
            if key is not None and key != self.last.get(name):
                self.last[name] = key
                say("EMOS", name, key)
        self.health_status.set_healthy()


class Services(BaseComponent):
    # Serves /emos_trigger (std_srvs Trigger) and calls the ROS 2 service /ros_setbool (SetBool).
    def custom_on_activate(self):
        from emos.msgs.registry import resolve
        self.Req, self.Resp = resolve("std_srvs/msg/SetBool_Request"), resolve("std_srvs/msg/SetBool_Response")
        self.answered = False
        self.create_service("/emos_trigger", "std_srvs/msg/Trigger_Request", "std_srvs/msg/Trigger_Response", trigger)

    def _execution_step(self):
        if self.answered or not os.path.exists(CALL_ON):
            self.health_status.set_healthy()
            return
        from emos.core.services import ServiceClient
        try:
            client = ServiceClient("/ros_setbool", self.Req, self.Resp, ctx=self.node.ctx, timeout=5.0)
            answer = client.call(self.Req(data=True))
            client.close()
            say("EMOS setbool answer", answer.success, answer.message)
            self.answered = True
        except Exception as exc:  # not bridged yet
            pass
        self.health_status.set_healthy()


def trigger(request):
    from emos.msgs.registry import resolve
    return resolve("std_srvs/msg/Trigger_Response")(success=True, message="emos answered")


services = Services(component_name="services")
services.config.loop_rate = 4.0

rt = RoundTrip(component_name="roundtrip", inputs=[Topic(name=topic_of(t) + "/back", msg_type=t) for t in TYPES],
               outputs=[Topic(name=topic_of(t), msg_type=t) for t in TYPES])
rt.config.loop_rate = 2.0
latched = QoSConfig(durability=TRANSIENT_LOCAL, queue_size=1)
sensors = Sensors(component_name="sensors", outputs=[Topic(name="scan", msg_type="LaserScan"), Topic(name="clash", msg_type="String"),
                  Topic(name="map", msg_type="OccupancyGrid", qos_profile=latched), Topic(name="tf", msg_type="tf2_msgs/msg/TFMessage"),
                  Topic(name="camera/image", msg_type="Image")])
sensors.config.loop_rate = 30.0
listener = Listener(component_name="listener", inputs=[Topic(name="chatter", msg_type="String"),
                    Topic(name="ros_map", msg_type="OccupancyGrid", qos_profile=latched)])
listener.config.loop_rate = 50.0
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[rt, sensors, listener, services])
launcher.add_pkg(components=[Ros2BridgeComponent(config=Ros2BridgeConfig(domain_id={domain}))], package_name="ros2", multiprocessing=True)
launcher.bringup()
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ros2run")
    domain, other = free_domains(2)
    shm_before = fastdds_names()
    system = SystemUnderTest(tmp, RECIPE.format(repo=str(REPO), types=TYPES, cam_on=str(tmp / "cam.on"), domain=domain))
    system.domain, system.other_domain, system.cam_on = domain, other, tmp / "cam.on"
    try:
        system.wait_up(components=["roundtrip", "sensors", "listener", "services", "ros2_bridge"])
        yield system
    finally:
        code = system.stop()
        print(system.output()[-3000:])
    assert code == 0
    assert system.leftovers() == []
    # The bridge talks UDP only: whatever Fast DDS files exist now were there before or belong to
    # peers that are still running (none: every test stops its own).
    assert fastdds_files() - shm_before == set()


def bridge_lines(system: SystemUnderTest, pattern: str) -> list[str]:
    return [line for line in system.output().splitlines() if re.search(pattern, line)]


def test_every_shared_type_goes_to_ros2_and_back_with_every_field_equal(run):
    relay = Peer("relay.py", run.domain, *[f"{topic_of(t)}:{topic_of(t)}/back:{t}" for t in TYPES])
    relay.wait_for(lambda line: line == "ready", what="ready")
    # 44 topics each way: Fast DDS matches every endpoint pair before the last type can come back, which
    # took over a minute beside two CPU hogs. The wait only bounds a hang.
    wait_until(lambda: len(bridge_lines(run, r"^RT ")) >= len(TYPES), 3 * HANG_S, what="every type back from ROS 2")
    results = dict(line.split()[1:3] for line in bridge_lines(run, r"^RT "))
    assert results == dict.fromkeys(TYPES, "equal")
    assert len(TYPES) >= 40  # every shared type whose ROS 2 package the wheels bring


def test_graph_shows_emos_side_with_its_names_and_types(run):
    listener = Peer("listener.py", run.domain, "/scan", "sensor_msgs/msg/LaserScan", "default")
    line = listener.wait_for(lambda line: line.startswith("graph "), what="the graph")
    graph = json.loads(line[6:])
    topics = dict((name, types) for name, types in graph["topics"])
    assert topics["/scan"] == ["sensor_msgs/msg/LaserScan"]
    assert topics["/map"] == ["nav_msgs/msg/OccupancyGrid"]
    assert "emos_bridge" in graph["nodes"]
    assert "/sensors/status" not in topics  # our own types stay on our side
    # What `emos topic list` reads to mark the bridged topics.
    state = json.loads((run.run_dir / "ros2_bridge.json").read_text())
    assert state["node"] == "/emos_bridge" and state["domain_id"] == run.domain
    assert state["topics"]["/scan"] == {"direction": "emos->ros2", "type": "sensor_msgs/msg/LaserScan"}
    listener.wait_for(lambda line: line.startswith("got s"), what="a scan")


def test_a_late_ros2_node_gets_the_latched_map_and_emos_gets_a_latched_ros2_map(run):
    late = Peer("listener.py", run.domain, "/map", "nav_msgs/msg/OccupancyGrid", "latched")
    late.wait_for(lambda line: line.startswith("got map1 "), what="the map published before it started")
    talker = Peer("talker.py", run.domain, "/ros_map", "nav_msgs/msg/OccupancyGrid", 5, "latched", "--prefix", "rosmap", "--count", 1)
    talker.wait_for(lambda line: line == "ready", what="ready")
    wait_until(lambda: "EMOS ros_map rosmap0" in run.output(), what="the ROS 2 map at the EMOS listener")
    assert bridge_lines(run, r"/ros_map .*ROS 2 -> EMOS, RELIABLE/TRANSIENT_LOCAL")


def test_incompatible_qos_is_reported_once_by_name(run):
    # /scan goes out VOLATILE; a subscriber asking TRANSIENT_LOCAL cannot be served.
    strict = Peer("listener.py", run.domain, "/scan", "sensor_msgs/msg/LaserScan", "latched")
    strict.wait_for(lambda line: line == "ready", what="ready")
    wait_until(lambda: bridge_lines(run, r"topic /scan .*incompatible.*DURABILITY"), what="the incompatible-QoS report")
    time.sleep(2.0)  # the peer stays incompatible: still one line
    assert len(bridge_lines(run, r"topic /scan .*incompatible")) == 1
    assert strict.got() == []


def test_bad_input_is_dropped_with_one_line_and_the_rest_keeps_flowing(run):
    garbage = Peer("talker.py", run.domain, "/chatter", "std_msgs/msg/String", 20, "default", "--prefix", "g", "--garbage-every", 3)
    unknown = Peer("talker.py", run.domain, "/weird", "test_msgs/msg/BasicTypes", 20, "default")
    clash = Peer("talker.py", run.domain, "/clash", "std_msgs/msg/Int32", 20, "default")
    for p in (garbage, unknown, clash):
        p.wait_for(lambda line: line == "ready", what="ready")
    wait_until(lambda: re.search(r"EMOS chatter g\d*[13-9]\b", run.output()), what="good samples around the bad ones")
    wait_until(lambda: bridge_lines(run, r"/chatter: a malformed std_msgs/msg/String sample"), what="the malformed-sample line")
    wait_until(lambda: bridge_lines(run, r"/weird not bridged: ROS 2 type test_msgs/msg/BasicTypes has no EMOS counterpart"), what="unknown type")
    wait_until(lambda: bridge_lines(run, r"/clash not bridged: type differs between the sides: EMOS std_msgs/msg/String, ROS 2 std_msgs/msg/Int32"),
               what="the type clash")
    # tf2_msgs is not among the wheels installed: /tf is refused naming the package to install.
    assert len(bridge_lines(run, r"/tf not bridged: tf2_msgs/msg/TFMessage needs the ROS 2 package tf2_msgs")) == 1
    time.sleep(1.5)  # 20 bad samples a second keep coming: still rate-limited
    assert len(bridge_lines(run, r"/chatter: a malformed")) <= 2
    assert len(bridge_lines(run, r"/weird not bridged")) == 1 and len(bridge_lines(run, r"/clash not bridged")) == 1
    assert run.state("ros2_bridge") == "active"


def test_a_ros2_node_that_dies_and_comes_back_resumes_its_stream(run):
    first = Peer("talker.py", run.domain, "/chatter", "std_msgs/msg/String", 20, "default", "--prefix", "a")
    wait_until(lambda: "EMOS chatter a" in run.output(), what="the first talker's messages")
    first.stop(signal.SIGKILL)
    second = Peer("talker.py", run.domain, "/chatter", "std_msgs/msg/String", 20, "default", "--prefix", "b")
    second.wait_for(lambda line: line == "ready", what="ready")
    wait_until(lambda: "EMOS chatter b" in run.output(), what="the second talker's messages")


def emos_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "emos", *args], check=False, capture_output=True, text=True, timeout=HANG_S)


def test_services_both_ways(run):
    # A ROS 2 client calls the EMOS component's Trigger service ...
    client = Peer("service.py", run.domain, "client", "/emos_trigger")
    assert client.wait_for(lambda line: line.startswith("answer "), what="the EMOS service's answer") == "answer True emos answered"
    # ... and the EMOS component calls a ROS 2 SetBool server.
    server = Peer("service.py", run.domain, "server", "/ros_setbool")
    server.wait_for(lambda line: line == "ready", what="ready")
    (run.cam_on.parent / (run.cam_on.name + ".call")).touch()
    wait_until(lambda: "EMOS setbool answer True ros:True" in run.output(), what="the ROS 2 service's answer at EMOS")
    state = json.loads((run.run_dir / "ros2_bridge.json").read_text())
    assert state["services"] == {"/emos_trigger": "emos->ros2", "/ros_setbool": "ros2->emos"}
    # `emos service list/call` reach the ROS 2 server through the bridge component, as any component's.
    listed = emos_cli("service", "list", "ros2_bridge", "--json", "--run", run.ctx.run_id)
    assert listed.returncode == 0, listed.stderr
    assert json.loads(listed.stdout) == [{"name": "/ros_setbool", "component": "ros2_bridge", "serving": True,
                                          "request": "std_srvs/msg/SetBool_Request", "response": "std_srvs/msg/SetBool_Response"}]
    called = emos_cli("service", "call", "ros2_bridge", "/ros_setbool", '{"data": false}', "--run", run.ctx.run_id)
    assert called.returncode == 0, called.stderr
    assert json.loads(called.stdout) == {"success": False, "message": "ros:False"}


def test_image_921600_bytes_at_30_hz_for_10_s_arrives_whole(run):
    listener = Peer("listener.py", run.domain, "/camera/image", "sensor_msgs/msg/Image", "default", "--crc")
    listener.wait_for(lambda line: line == "ready", what="ready")
    run.cam_on.touch()
    listener.wait_for(lambda line: line.startswith("got "), what="a first frame")
    time.sleep(10.0)
    run.cam_on.unlink()
    time.sleep(1.0)
    got = listener.got()
    seqs = [int(line.split()[1]) for line in got]
    corrupt = [line for line in got if not line.endswith(" ok")]
    span = max(seqs) - min(seqs) + 1
    print(f"Image 921,600 B at 30 Hz: {len(seqs)} received of {span} sent in their span, {span - len(set(seqs))} dropped, "
          f"{len(corrupt)} corrupt")
    assert corrupt == []
    assert len(set(seqs)) == len(seqs) and seqs == sorted(seqs)


def test_the_bridge_sigkilled_is_restarted_streams_resume_and_nothing_is_left(run):
    pid = run.pid("ros2_bridge")
    assert dds_segments(pid) == []  # UDP only: no shared-memory segments to leave behind
    before = fastdds_names()
    listener = Peer("listener.py", run.domain, "/scan", "sensor_msgs/msg/LaserScan", "default")
    talker = Peer("talker.py", run.domain, "/chatter", "std_msgs/msg/String", 20, "default", "--prefix", "k")
    listener.wait_for(lambda line: line.startswith("got s"), what="scans before the kill")
    wait_until(lambda: "EMOS chatter k" in run.output(), what="chatter before the kill")
    os.kill(pid, signal.SIGKILL)
    new = run.wait_new_pid("ros2_bridge", pid)
    assert new != pid
    n = len(listener.got())
    listener.wait_for(lambda line: line.startswith("got s") and len(listener.got()) > n + 3, what="scans after the restart")
    talker.stop()
    again = Peer("talker.py", run.domain, "/chatter", "std_msgs/msg/String", 20, "default", "--prefix", "r")
    again.wait_for(lambda line: line == "ready", what="ready")
    wait_until(lambda: "EMOS chatter r" in run.output(), what="chatter after the restart")
    assert dds_segments(new) == []
    # The killed bridge left no Fast DDS file: whatever is new belongs to a live peer (peers use
    # shared memory), and the module's teardown checks that nothing is left once they are gone.
    assert {n for n in fastdds_files() - before if not n.endswith("_el") and not n.startswith("sem.")} <= mapped_by_peers()


def dds_segments(pid: int) -> list[str]:
    with open(f"/proc/{pid}/maps") as f:
        return [line for line in f if "/dev/shm/" in line and ("fastrtps" in line or "fastdds" in line)]


def mapped_by_peers() -> set[str]:
    out = set()
    for peer in list(_PEERS):
        try:
            out |= {line.rsplit("/", 1)[-1].strip() for line in dds_segments(peer.proc.pid)}
        except OSError:
            continue
    return out


def test_two_runs_on_different_domains_do_not_see_each_other(run, tmp_path):
    # This run asks for its bridge the recipe's way (use_ros2), added through the frontend's
    # request/add as the Launcher does for `emos run --ros2`.
    other = SystemUnderTest(tmp_path, f"""
from emos.actors.ros2 import frontend
from emos.transport.select import use_ros2

class Reader(BaseComponent):
    def _execution_step(self):
        m = self.get_input("scan")
        if m is not None:
            print("OTHER got scan", flush=True)
        self.health_status.set_healthy()

reader = Reader(component_name="reader", inputs=[Topic(name="scan", msg_type="LaserScan")])
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[reader])
print("USING", use_ros2(topics="all", domain_id={run.other_domain}), flush=True)
frontend.add(launcher, frontend.request())
launcher.bringup()
""")
    try:
        other.wait_up(components=["reader", "ros2_bridge"])
        assert "USING ROS 2 jazzy (rclpy" in other.output()
        # The other run's bridge works on its domain ...
        talker = Peer("talker.py", run.other_domain, "/ping", "std_msgs/msg/String", 10, "default")
        talker.wait_for(lambda line: line == "ready", what="ready")
        wait_until(lambda: "/ping (std_msgs/msg/String) ROS 2 -> EMOS" in other.output(), what="the other run bridging /ping")
        listener = Peer("listener.py", run.other_domain, "/scan", "sensor_msgs/msg/LaserScan", "default")
        graph = json.loads(listener.wait_for(lambda line: line.startswith("graph "), what="the graph")[6:])
        # ... and sees nothing of the first run's: none of its topics (/scan is there only as
        # the listener's own subscription), one bridge node, no scan delivered.
        topics = dict((n, t) for n, t in graph["topics"])
        assert "/map" not in topics and not [t for t in topics if t.startswith("/rt/")]
        assert graph["nodes"].count("emos_bridge") == 1
        assert "/ping" not in run.output() and "OTHER got scan" not in other.output()
        assert listener.got() == []
    finally:
        assert other.stop() == 0
