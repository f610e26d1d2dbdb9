"""The Foxglove bridge, spoken to as Foxglove does: a WebSocket client of the foxglove.websocket.v1 protocol."""
from __future__ import annotations

import asyncio
import json
import re
import struct
import subprocess
import sys
import time
import zlib

import numpy as np
import pytest

pytest.importorskip("foxglove")
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
