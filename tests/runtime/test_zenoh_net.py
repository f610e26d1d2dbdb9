"""Topics between two runs over Zenoh only: images and scans cross with no shared segment, the
stream resumes when the publishing run is killed and restarted, and foreign payloads on the
topic's key are dropped with a log line while the subscriber keeps delivering."""
import contextlib
import json
import os
import shutil
import socket
import subprocess
import sys
import time
import uuid

import pytest

from emos.transport.context import SHM_DIR
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process

zenoh = pytest.importorskip("zenoh", reason="the 'net' extra (eclipse-zenoh) is not installed")

CAMERA = """
class Camera(BaseComponent):
    def custom_on_activate(self):
        self.n = 0
    def _execution_step(self):
        self.n += 1
        img = M.Image(height=480, width=640, encoding="rgb8", step=1920, data=np.full(921600, self.n % 251, dtype=np.uint8))
        img.header.frame_id = f"run{os.environ['SIDE']}-{self.n}"
        self.publish(self.out_topics[0], img)
        self.publish(self.out_topics[1], M.LaserScan(ranges=np.full(360, float(self.n), dtype=np.float32)))
        self.health_status.set_healthy()

cam = Camera(component_name="camera", outputs=[Topic(name="cam", msg_type="Image"), Topic(name="scan", msg_type="LaserScan")])
cam.config.loop_rate = 20
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[cam])
launcher.bringup()
"""

VIEWER = """
class Viewer(BaseComponent):
    def custom_on_activate(self):
        self.seen = []
    def _execution_step(self):
        img, scan = self.node.latest("cam"), self.node.latest("scan")
        if img is not None and scan is not None:
            ok = img.width == 640 and img.data.nbytes == 921600 and bool((img.data == img.data[0]).all()) and scan.ranges.shape == (360,)
            if ok and (not self.seen or self.seen[-1] != img.header.frame_id):
                self.seen.append(img.header.frame_id)
                with open("seen.json.tmp", "w") as f:
                    json.dump(self.seen[-50:], f)
                os.replace("seen.json.tmp", "seen.json")
        self.health_status.set_healthy()

import json
viewer = Viewer(component_name="viewer", inputs=[Topic(name="cam", msg_type="Image"), Topic(name="scan", msg_type="LaserScan")])
viewer.config.loop_rate = 20
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[viewer])
launcher.bringup()
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _config(path, listen: str, connect: str) -> str:
    # Explicit endpoints, no multicast scouting: the two runs find each other by their endpoints
    # and nothing else on this shared machine joins in.
    path.write_text(json.dumps({
        "mode": "peer",
        "listen": {"endpoints": [f"tcp/{listen}"]},
        "connect": {"endpoints": [f"tcp/{connect}"]},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
    }))
    return str(path)


def _seen(folder) -> list[str]:
    try:
        return json.loads((folder / "seen.json").read_text())
    except (FileNotFoundError, ValueError):
        return []


def _last_frame(folder) -> int:
    """The camera's counter in the newest image the viewer saw (the file keeps the last 50)."""
    seen = _seen(folder)
    return int(seen[-1].rsplit("-", 1)[1]) if seen else 0


def _walk(node):
    yield node
    for child in node.get("children", []):
        yield from _walk(child)


def _segments_of(system) -> list[str]:
    return [n for n in os.listdir(SHM_DIR) if system.ctx is not None and n.startswith(system.ctx.shm_prefix)]


def _run(cmd: list[str]) -> None:
    subprocess.run(cmd, check=True, capture_output=True, timeout=10)


@contextlib.contextmanager
def _namespaces():
    """Two network namespaces joined by a private veth pair (10.254.16.1 and .2/30, which exist
    only inside them): ``(prefix A, prefix B, address A, address B)``. Skips without root."""
    if os.geteuid() != 0 or shutil.which("ip") is None:
        pytest.skip("separate network namespaces need root and iproute2")
    tag = uuid.uuid4().hex[:6]
    ns_a, ns_b, veth_a, veth_b = f"emos-{tag}-a", f"emos-{tag}-b", f"ez{tag}a", f"ez{tag}b"
    made = []
    try:
        for ns in (ns_a, ns_b):
            _run(["ip", "netns", "add", ns])
            made.append(ns)
        _run(["ip", "link", "add", veth_a, "netns", ns_a, "type", "veth", "peer", "name", veth_b, "netns", ns_b])
        for ns, dev, addr in ((ns_a, veth_a, "10.254.16.1/30"), (ns_b, veth_b, "10.254.16.2/30")):
            _run(["ip", "-n", ns, "addr", "add", addr, "dev", dev])
            _run(["ip", "-n", ns, "link", "set", dev, "up"])
            _run(["ip", "-n", ns, "link", "set", "lo", "up"])
    except (subprocess.CalledProcessError, subprocess.TimeoutExpired) as exc:
        for ns in made:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        pytest.skip(f"cannot set up network namespaces here: {exc}")
    try:
        yield ["ip", "netns", "exec", ns_a], ["ip", "netns", "exec", ns_b], "10.254.16.1", "10.254.16.2"
    finally:
        for ns in made:  # deleting a namespace removes its end of the veth pair, and so the pair
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)


@contextlib.contextmanager
def _loopback():
    yield [], [], "127.0.0.1", "127.0.0.1"


def _intrude(prefix: list[str], endpoint: str, key: str) -> None:
    """Put a foreign payload, a frame header with garbage after it, random bytes, and a frame
    of the right type whose body does not decode (it passes the check on Zenoh's thread and
    must be dropped where the node decodes it) on ``key``, from a Zenoh client in the
    subscriber's network (namespace)."""
    script = (
        "import json, os, sys, time, zenoh\n"
        "conf = zenoh.Config()\n"
        "conf.insert_json5('mode', '\"client\"')\n"
        "conf.insert_json5('connect/endpoints', json.dumps([sys.argv[1]]))\n"
        "conf.insert_json5('scouting/multicast/enabled', 'false')\n"
        "with zenoh.open(conf) as s:\n"
        "    fp = sys.argv[3].encode()\n"
        "    framed = b'EMZ1' + bytes(8) + len(fp).to_bytes(2, 'little') + b'\\x00\\x00' + fp + (3).to_bytes(4, 'little') + b'\\xc1' * 4\n"
        "    for _ in range(10):  # a few seconds: on a loaded machine the route may take a while\n"
        "        time.sleep(0.5)\n"
        "        for p in (b'not an emos frame', b'EMZ1' + bytes(8) + b'\\x10\\x00\\x00\\x00' + b'f' * 16, os.urandom(4096), framed):\n"
        "            s.put(sys.argv[2], p)\n"
        "    time.sleep(0.3)\n"
    )
    from emos.msgs import Image

    subprocess.run([*prefix, sys.executable, "-c", script, f"tcp/{endpoint}", key, Image._emos_fingerprint], check=True, timeout=30)


@pytest.mark.parametrize("network", ["loopback", "namespaces"])
def test_two_runs_exchange_images_and_scans_over_zenoh_and_resume_after_a_kill(tmp_path, network):
    with (_namespaces() if network == "namespaces" else _loopback()) as (prefix_a, prefix_b, addr_a, addr_b):
        _exchange(tmp_path, prefix_a, prefix_b, addr_a, addr_b)


def _exchange(tmp_path, prefix_a, prefix_b, addr_a, addr_b):
    group = f"t{uuid.uuid4().hex[:10]}"
    port_a, port_b = _free_port(), _free_port()
    end_a, end_b = f"{addr_a}:{port_a}", f"{addr_b}:{port_b}"
    dirs = {name: tmp_path / name for name in ("a", "a2", "b")}
    for d in dirs.values():
        d.mkdir()
    env_common = {"EMOS_NET_GROUP": group, "EMOS_NET_TOPICS": "/cam,/scan"}
    env_a = {**env_common, "SIDE": "A", "EMOS_ZENOH_CONFIG": _config(tmp_path / "a.json5", end_a, end_b)}
    env_b = {**env_common, "EMOS_ZENOH_CONFIG": _config(tmp_path / "b.json5", end_b, end_a)}

    viewer = SystemUnderTest(dirs["b"], VIEWER, env=env_b, prefix=prefix_b).wait_up(components=["viewer"], timeout=60)
    camera = SystemUnderTest(dirs["a"], CAMERA, env=env_a, prefix=prefix_a).wait_up(components=["camera"], timeout=60)
    assert camera.ctx.run_id != viewer.ctx.run_id
    try:
        wait_until(lambda: len(_seen(dirs["b"])) >= 5, timeout=60, what="images from run A over Zenoh")
        # Only Zenoh carried them: neither run has a ring for /cam or /scan.
        for system in (camera, viewer):
            assert not [n for n in _segments_of(system) if ".cam." in n or ".scan." in n], _segments_of(system)

        # Discovery across the network: `emos topic list --network` in run B's network, no run of its own.
        client = tmp_path / "client.json5"
        client.write_text(json.dumps({"mode": "client", "connect": {"endpoints": [f"tcp/{end_b}"]}, "scouting": {"multicast": {"enabled": False}}}))
        listed = subprocess.run([*prefix_b, sys.executable, "-m", "emos", "topic", "list", "--network", str(client), "--json"],
                                capture_output=True, text=True, timeout=60, env={**os.environ, "EMOS_NET_GROUP": group})
        assert listed.returncode == 0, listed.stderr
        topics = json.loads(listed.stdout)
        assert topics["/cam"]["publishers"] == ["camera"] and topics["/cam"]["type"].endswith("Image"), topics
        assert topics["/scan"]["type"].endswith("LaserScan")

        # A foreign payload on the topic's key, and a frame of the wrong type: dropped and logged.
        _intrude(prefix_b, end_b, f"emos/{group}/cam")
        wait_until(lambda: "dropping a payload on key emos/" + group + "/cam" in viewer.output(), timeout=20, what="the foreign payload's log line")
        last = _last_frame(dirs["b"])
        wait_until(lambda: _last_frame(dirs["b"]) > last + 3, timeout=30, what="delivery to go on after the foreign payloads")
        assert viewer.state("viewer") == "active"

        # Kill the publishing run outright and start it again: the stream resumes.
        camera.kill_all()
        time.sleep(1.0)
        before = _seen(dirs["b"])[-1]
        env_a2 = {**env_a, "SIDE": "A2"}
        camera = SystemUnderTest(dirs["a2"], CAMERA, env=env_a2, prefix=prefix_a).wait_up(components=["camera"], timeout=60)
        wait_until(lambda: any(s.startswith("runA2-") for s in _seen(dirs["b"])), timeout=60, what="images from the restarted run")
        assert before.startswith("runA-")
        assert viewer.state("viewer") == "active"
    finally:
        camera.stop()
        assert viewer.stop() == 0
    assert viewer.leftovers() == []


def test_a_service_and_an_action_served_over_zenoh_to_a_process_outside_the_run(tmp_path, capsys):
    """The serving run shares its service and action over Zenoh; this test process, in no run
    and with no access to its sockets' directory in the client's code path, calls them."""
    from emos import msgs as M
    from emos.core.services import ActionCanceled
    from emos.transport import zenoh_net
    from emos.transport.zenoh_rpc import NetActionClient, NetServiceClient, RemoteServiceError, ServiceUnavailable
    from tests.runtime.test_component import SERVICES_RECIPE

    group = f"t{uuid.uuid4().hex[:10]}"
    port_server, port_client = _free_port(), _free_port()
    env = {"EMOS_NET_GROUP": group, "EMOS_NET_SERVICES": "adder/service,/counter/action",
           "EMOS_ZENOH_CONFIG": _config(tmp_path / "server.json5", f"127.0.0.1:{port_server}", f"127.0.0.1:{port_client}")}
    client_conf = _config(tmp_path / "client.json5", f"127.0.0.1:{port_client}", f"127.0.0.1:{port_server}")
    system = SystemUnderTest(tmp_path, SERVICES_RECIPE, env=env).wait_up(components=["adder", "counter"], timeout=60)
    old_group = os.environ.get("EMOS_NET_GROUP")
    os.environ["EMOS_NET_GROUP"] = group
    try:
        srv = NetServiceClient("/adder/service", "SetBool_Request", "SetBool_Response", timeout=5.0, config_path=client_conf)

        def call():
            try:
                return srv.call(M.SetBoolRequest(data=True))
            except ServiceUnavailable:
                return None

        reply = wait_until(call, timeout=30, what="the service over Zenoh")
        assert reply.success is True and f"pid {system.pid('adder')}" in reply.message

        action = NetActionClient("/counter/action", "Int64", "Int64", "String", config_path=client_conf)

        def reachable():
            try:
                return action.cancel("no-such-goal") is False  # answered: the server is there
            except ServiceUnavailable:
                return False

        wait_until(reachable, timeout=30, what="the action over Zenoh")
        feedback = []
        result = action.send_goal(M.Int64(data=5), feedback_callback=lambda fb: feedback.append(fb.data), timeout=30)
        assert result.data == "counted to 5" and feedback == [0, 1, 2, 3, 4]

        outcome = {}
        import threading

        def long_goal():
            try:
                outcome["r"] = action.send_goal(M.Int64(data=500), goal_id="long", timeout=60)
            except Exception as exc:  # noqa: BLE001 - the test inspects it
                outcome["r"] = exc

        t = threading.Thread(target=long_goal)
        t.start()
        wait_until(lambda: action.cancel("long") is True, timeout=20, what="the remote cancel")
        t.join(30)
        assert isinstance(outcome["r"], ActionCanceled)

        # The supervisor's status, from outside the run: what `emos status --remote` prints.
        import argparse

        from emos.tools.cli import status as cli_status

        def remote_tree():
            capsys.readouterr()
            code = cli_status.run(argparse.Namespace(remote=client_conf, json=True, watch=0.0, run=None))
            runs = json.loads(capsys.readouterr().out)
            return code == 0 and runs

        runs = wait_until(remote_tree, timeout=30, what="the run's status over Zenoh")
        assert [r["run_id"] for r in runs] == [system.ctx.run_id]
        workers = {n["name"]: n for n in _walk(runs[0]["tree"]) if n.get("kind") == "worker"}
        assert workers["adder"]["pid"] == system.pid("adder") and workers["counter"]["state"] == "active"

        # A malformed query gets an error reply naming the problem; the bridge keeps serving.
        sess = zenoh_net.session(client_conf)
        replies = list(sess.get(f"emos/{group}/_srv_/adder/service", payload=b"\xc1 not msgpack", timeout=10))
        assert replies and replies[0].ok is None
        with pytest.raises(RemoteServiceError, match="not msgpack"):
            from emos.transport.zenoh_rpc import _unpack_reply

            _unpack_reply("service", replies[0])
        assert srv.call(M.SetBoolRequest(data=False)).message.startswith("call ")
    finally:
        zenoh_net.close_sessions()
        if old_group is None:
            os.environ.pop("EMOS_NET_GROUP", None)
        else:
            os.environ["EMOS_NET_GROUP"] = old_group
        assert system.stop() == 0
    assert system.leftovers() == []
