"""The Foxglove bridge, spoken to as Foxglove does: a WebSocket client of the foxglove.websocket.v1 protocol."""
from __future__ import annotations

import asyncio
import json
import os
import re
import struct
import subprocess
import sys
import time
import zlib

import numpy as np
import pytest

pytest.importorskip("foxglove")

pytestmark = pytest.mark.process
websockets = pytest.importorskip("websockets")

from rosbags.typesys import Stores, get_typestore  # noqa: E402

from tests.runtime.helpers import SystemUnderTest, wait_until  # noqa: E402

RECIPE = """
import zlib
from emos.msgs import Header, Image, LaserScan, Time, TransformStamped
from emos.msgs.geometry import TFMessage

class Sensors(BaseComponent):
    def custom_on_activate(self):
        self.seq = 0

    def _execution_step(self):
        ranges = (1.0 + 0.01 * np.arange(360)).astype(np.float32)
        self.publish("scan", LaserScan(header=Header(stamp=Time.now(), frame_id="laser"), angle_min=-3.0, angle_max=3.0,
                                       angle_increment=6.0 / 359, range_min=0.1, range_max=20.0, ranges=ranges))
        pixels = np.full((48, 64, 3), self.seq % 256, np.uint8)
        crc = zlib.crc32(pixels.data) & 0xFFFFFFFF
        self.publish("camera/rgb", Image.from_numpy(pixels, "rgb8", header=Header(stamp=Time.now(), frame_id=f"{self.seq}:{crc}")))
        tf = TransformStamped(header=Header(stamp=Time.now(), frame_id="odom"), child_frame_id="base_link")
        tf.transform.translation.x = 1.5
        self.publish("tf_base", tf)
        self.publish("tf", TFMessage(transforms=[tf]))
        self.seq += 1
        self.health_status.set_healthy()

topics = [Topic(name="scan", msg_type="LaserScan"), Topic(name="camera/rgb", msg_type="Image"), Topic(name="tf_base", msg_type="TransformStamped"),
          Topic(name="tf", msg_type="tf2_msgs/msg/TFMessage")]
sensors = Sensors(component_name="sensors", outputs=topics)
sensors.config.loop_rate = 10.0
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[sensors])
launcher.enable_foxglove(port=0)
launcher.bringup()
"""

STORE = get_typestore(Stores.ROS2_HUMBLE)
SUBPROTOCOLS = ["foxglove.websocket.v1", "foxglove.sdk.v1"]


async def foxglove_session(url: str, want: dict[str, int], timeout: float = 20.0) -> tuple[dict, dict]:
    """Connect, collect advertisements, subscribe to ``want`` topics; returns (channels by topic, payloads by topic)."""
    channels: dict[str, dict] = {}
    payloads: dict[str, list[bytes]] = {t: [] for t in want}
    subscribed: dict[int, str] = {}
    # foxglove-sdk 0.30 names the protocol foxglove.sdk.v1 (the foxglove.websocket.v1 message set:
    # same JSON ops, same binary framing); we offer both names, as Foxglove does.
    async with websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None) as ws:
        assert ws.subprotocol in SUBPROTOCOLS
        deadline = time.monotonic() + timeout
        while any(len(payloads[t]) < n for t, n in want.items()):
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out: advertised {sorted(channels)}, received { {t: len(p) for t, p in payloads.items()} }")
            raw = await asyncio.wait_for(ws.recv(), timeout=max(deadline - time.monotonic(), 0.1))
            if isinstance(raw, str):
                msg = json.loads(raw)
                if msg["op"] == "advertise":
                    new = []
                    for ch in msg["channels"]:
                        channels[ch["topic"]] = ch
                        if ch["topic"] in want:
                            sub_id = len(subscribed) + 1
                            subscribed[sub_id] = ch["topic"]
                            new.append({"id": sub_id, "channelId": ch["id"]})
                    if new:
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                continue
            opcode = raw[0]
            if opcode != 0x01:  # message data; other binary ops (time, ...) are not ours
                continue
            sub_id, _log_time = struct.unpack_from("<IQ", raw, 1)
            payloads[subscribed[sub_id]].append(raw[13:])
    return channels, payloads


def decode_protobuf(channel: dict, data: bytes):
    """Decode with the schema the server advertised (a base64 FileDescriptorSet), as Foxglove does."""
    import base64

    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for f in files.file:
        pool.Add(f)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))
    return cls.FromString(data)


def test_launcher_foxglove_component_serves_scans_and_images(tmp_path):
    system = SystemUnderTest(tmp_path, RECIPE).wait_up(components=["sensors", "foxglove_bridge"])
    port = int(wait_until(lambda: re.search(r"Foxglove: ws://127\.0\.0\.1:(\d+)", system.output()), 20, what="the bridge's port").group(1))
    channels, payloads = asyncio.run(foxglove_session(f"ws://127.0.0.1:{port}", {"/scan": 2, "/camera/rgb": 2}))

    scan_ch = channels["/scan"]
    assert (scan_ch["encoding"], scan_ch["schemaName"], scan_ch["schemaEncoding"]) == ("cdr", "sensor_msgs/msg/LaserScan", "ros2msg")
    assert "MSG: std_msgs/Header" in scan_ch["schema"]
    assert channels["/camera/rgb"]["schemaName"] == "sensor_msgs/msg/Image"
    # Transforms go as Foxglove's own schema, our other types as JSON.
    assert channels["/tf_base"]["schemaName"] == "foxglove.FrameTransforms"
    assert channels["/sensors/status"]["encoding"] == "json"

    # Decoded with rosbags' ROS 2 definitions, independently of the bridge's conversion code.
    scan = STORE.deserialize_cdr(payloads["/scan"][0], "sensor_msgs/msg/LaserScan")
    assert scan.header.frame_id == "laser"
    np.testing.assert_allclose(scan.ranges, 1.0 + 0.01 * np.arange(360), rtol=1e-6)
    for data in payloads["/camera/rgb"]:
        img = STORE.deserialize_cdr(data, "sensor_msgs/msg/Image")
        assert (img.height, img.width, img.encoding, img.step) == (48, 64, "rgb8", 192)
        seq, crc = img.header.frame_id.split(":")
        assert zlib.crc32(np.ascontiguousarray(img.data).data) & 0xFFFFFFFF == int(crc)
        assert int(img.data[0]) == int(seq) % 256

    # The same bridge from outside the system: `emos viz`, with a JSON status and a transform.
    viz = subprocess.Popen([sys.executable, "-m", "emos", "viz", "--run", system.ctx.run_id, "--port", "0", "-q"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = viz.stdout.readline()
        port2 = int(re.search(r"ws://127\.0\.0\.1:(\d+)", line).group(1))
        channels2, payloads2 = asyncio.run(foxglove_session(f"ws://127.0.0.1:{port2}", {"/sensors/status": 1, "/tf_base": 1, "/tf": 1}))
        status = json.loads(payloads2["/sensors/status"][0])
        assert status["status"] == 0 and status["lifecycle_state"] == "active"
        assert channels2["/tf_base"]["encoding"] == "protobuf"
        tf = decode_protobuf(channels2["/tf_base"], payloads2["/tf_base"][0])
        assert [(t.parent_frame_id, t.child_frame_id, t.translation.x) for t in tf.transforms] == [("odom", "base_link", 1.5)]
        assert channels2["/tf"]["schemaName"] == "tf2_msgs/msg/TFMessage" and channels2["/tf"]["encoding"] == "cdr"
        ros_tf = STORE.deserialize_cdr(payloads2["/tf"][0], "tf2_msgs/msg/TFMessage")
        assert [(t.child_frame_id, t.transform.translation.x) for t in ros_tf.transforms] == [("base_link", 1.5)]
    finally:
        viz.terminate()
        out, err = viz.communicate(timeout=20)
    assert viz.returncode == 0, err
    assert system.stop() == 0


# --- Who may connect (issue 31 item 4): browsers of foreign origins are refused at the handshake,
# and with a token nobody gets in without it.

CAMERA = """
class Camera(BaseComponent):
    def _execution_step(self):
        self.publish("camera/rgb", M.Image.from_numpy(np.full((8, 8, 3), 7, np.uint8), "rgb8"))
        self.health_status.set_healthy()

camera = Camera(component_name="camera", outputs=[Topic(name="camera/rgb", msg_type="Image")])
camera.config.loop_rate = 10.0
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[camera])
launcher.bringup()
"""


class Viz:
    """``emos viz`` on a free port, with its printed URL."""

    def __init__(self, run_id: str, *extra: str):
        env = {k: v for k, v in os.environ.items() if k != "EMOS_FOXGLOVE_TOKEN"}
        self.proc = subprocess.Popen([sys.executable, "-m", "emos", "viz", "--run", run_id, "--port", "0", "-q", *extra],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        line = self.proc.stdout.readline()
        m = re.search(r"(ws://127\.0\.0\.1:(\d+)\S*)", line)
        if m is None:
            self.proc.kill()
            raise AssertionError(f"emos viz printed {line!r}; stderr: {self.proc.communicate(timeout=20)[1]}")
        self.url, self.port = m.group(1), int(m.group(2))

    def stop(self) -> str:
        self.proc.terminate()
        _out, err = self.proc.communicate(timeout=20)
        assert self.proc.returncode == 0, err
        return err


async def handshake_status(url: str, origin: str | None = None, headers: dict | None = None) -> int:
    """101 if the WebSocket handshake succeeded, else the HTTP status of the refusal."""
    try:
        async with websockets.connect(url, subprotocols=SUBPROTOCOLS, origin=origin, additional_headers=headers,
                                      open_timeout=20):
            return 101
    except websockets.exceptions.InvalidStatus as exc:
        return exc.response.status_code


async def receive_camera(url: str, origin: str | None) -> bytes:
    """Subscribe to /camera/rgb as Foxglove in a browser of ``origin`` would; returns one payload."""
    async with websockets.connect(url, subprotocols=SUBPROTOCOLS, origin=origin, max_size=None, open_timeout=20) as ws:
        while True:
            raw = await asyncio.wait_for(ws.recv(), timeout=20)
            if isinstance(raw, str):
                msg = json.loads(raw)
                for ch in msg.get("channels", []) if msg["op"] == "advertise" else []:
                    if ch["topic"] == "/camera/rgb":
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": ch["id"]}]}))
            elif raw[0] == 0x01:
                return raw[13:]


def test_viz_refuses_foreign_origins_and_serves_foxglove(tmp_path):
    system = SystemUnderTest(tmp_path, CAMERA).wait_up(components=["camera"])
    viz = Viz(system.ctx.run_id)
    try:
        # A page on any other site, and a sandboxed page or file: (Origin: null), get nothing.
        assert asyncio.run(handshake_status(viz.url, "https://evil.example")) == 403
        assert asyncio.run(handshake_status(viz.url, "null")) == 403
        assert asyncio.run(handshake_status(viz.url, "http://localhost.evil.example")) == 403
        assert asyncio.run(handshake_status(viz.url, "https://foxglove.dev.evil.example")) == 403
        # Foxglove's web app, a localhost page on any port, and a non-browser client (no Origin, no token set) do.
        img = STORE.deserialize_cdr(asyncio.run(receive_camera(viz.url, "https://app.foxglove.dev")), "sensor_msgs/msg/Image")
        assert (img.height, img.width, int(img.data[0])) == (8, 8, 7)
        assert asyncio.run(handshake_status(viz.url, "http://localhost:3000")) == 101
        assert asyncio.run(handshake_status(viz.url, "http://[::1]:8080")) == 101
        assert asyncio.run(handshake_status(viz.url)) == 101
    finally:
        err = viz.stop()
    assert "refused a connection" in err and "evil.example" in err
    # --allow-origin adds to the list.
    viz = Viz(system.ctx.run_id, "--allow-origin", "https://*.example.org:*", "--allow-origin", "file://")
    try:
        assert asyncio.run(handshake_status(viz.url, "https://viewer.example.org:8443")) == 101
        assert asyncio.run(handshake_status(viz.url, "file://")) == 101  # exact origins, e.g. a desktop app's
        assert asyncio.run(handshake_status(viz.url, "https://example.org.evil.example")) == 403
        assert asyncio.run(handshake_status(viz.url, "null")) == 403
    finally:
        viz.stop()
    assert system.stop() == 0


def test_viz_token_required_on_the_handshake(tmp_path):
    system = SystemUnderTest(tmp_path, CAMERA).wait_up(components=["camera"])
    viz = Viz(system.ctx.run_id, "--token", "auto")
    try:
        token = re.search(r"\?token=([A-Za-z0-9_-]+)$", viz.url).group(1)
        bare = f"ws://127.0.0.1:{viz.port}/"
        assert asyncio.run(handshake_status(bare)) == 401                     # a local program without it
        assert asyncio.run(handshake_status(bare, "https://app.foxglove.dev")) == 401  # an allowed origin without it
        assert asyncio.run(handshake_status(f"{bare}?token=x{token}")) == 401
        assert asyncio.run(handshake_status(viz.url, "https://evil.example")) == 403   # the token does not excuse the origin
        assert asyncio.run(handshake_status(bare, headers={"Authorization": f"Bearer {token}"})) == 101
        img = STORE.deserialize_cdr(asyncio.run(receive_camera(viz.url, "https://app.foxglove.dev")), "sensor_msgs/msg/Image")
        assert (img.height, img.width) == (8, 8)
    finally:
        err = viz.stop()
    assert token not in err  # printed once, on stdout, not in the log
    assert system.stop() == 0


def test_viz_on_a_network_address_requires_a_token():
    from emos.actors.viz import FoxgloveBridgeComponent, FoxgloveConfig

    env = {k: v for k, v in os.environ.items() if k != "EMOS_FOXGLOVE_TOKEN"}
    proc = subprocess.run([sys.executable, "-m", "emos", "viz", "--host", "0.0.0.0", "--port", "0"],
                          capture_output=True, text=True, timeout=60, env=env)
    assert proc.returncode != 0 and "--token" in proc.stderr and "0.0.0.0" in proc.stderr
    with pytest.raises(ValueError, match="token"):
        FoxgloveBridgeComponent(config=FoxgloveConfig(host="0.0.0.0"))
    with pytest.raises(ValueError, match="token"):
        FoxgloveConfig(token="short")
    with pytest.raises(ValueError, match="allow_origins"):
        FoxgloveConfig(allow_origins=["evil.example"])
    FoxgloveBridgeComponent(config=FoxgloveConfig(host="0.0.0.0", token="auto"))


def test_gate_forwards_the_handshake_without_the_token_and_refuses_malformed_ones():
    """The gate alone, in front of a plain TCP server that records what reaches it."""
    import socket
    import threading

    from emos.interop.foxglove_gate import HandshakeGate

    upstream = socket.create_server(("127.0.0.1", 0))
    received: list[bytes] = []

    def serve():
        conn, _ = upstream.accept()
        with conn:
            data = b""
            while b"\r\n\r\n" not in data:
                data += conn.recv(4096)
            received.append(data)
            conn.sendall(b"HTTP/1.1 101 Switching Protocols\r\n\r\nhello")

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    gate = HandshakeGate("127.0.0.1", 0, upstream.getsockname(), token="s3cret-token")

    def exchange(request: bytes) -> bytes:
        with socket.create_connection(("127.0.0.1", gate.port), timeout=20) as s:
            s.sendall(request)
            out = b""
            while chunk := s.recv(4096):
                out += chunk
                if out.endswith(b"hello"):
                    break
            return out

    try:
        two_origins = b"GET / HTTP/1.1\r\nOrigin: http://localhost\r\nOrigin: https://evil.example\r\n\r\n"
        assert exchange(two_origins).startswith(b"HTTP/1.1 400")
        assert exchange(b"POST /?token=s3cret-token HTTP/1.1\r\n\r\n").startswith(b"HTTP/1.1 405")
        assert exchange(b"\x16\x03\x01 not http\r\n\r\n").startswith(b"HTTP/1.1 400")
        reply = exchange(b"GET /?a=1&token=s3cret-token HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer nope\r\n\r\n")
        assert reply.endswith(b"hello")
        t.join(timeout=20)
        assert received == [b"GET /?a=1 HTTP/1.1\r\nHost: x\r\n\r\n"]  # the token and credentials stay with the gate
        assert (gate.refused, gate.accepted) == (3, 1)
    finally:
        gate.close()
        upstream.close()
