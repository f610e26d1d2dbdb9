"""The runtime demo: sensors in their own processes, a checking consumer, and a crashing component.

    emos run recipes/sensor_demo.py --duration 20

* ``camera``: 640x480 RGB frames at 30 Hz (921,600 B each, through shared memory);
* ``lidar``: 720-beam LaserScans at 20 Hz;
* ``checker``: receives both, verifies every message's checksum and sequence number, measures
  the publish-to-receive latency, and prints a report when it stops;
* ``crasher``: kills itself with SIGKILL every 3 s; the supervisor brings it back each time.

Each sensor stamps ``header.frame_id`` with ``<sequence>:<crc32 of the payload>``, so a torn,
corrupted, lost or duplicated message is counted, not guessed.
"""
import os
import signal
import time
import zlib

import numpy as np

from emos import BaseComponent, Launcher, Topic
from emos.msgs import Header, Image, LaserScan, Time

WIDTH, HEIGHT = 640, 480
BEAMS = 720
CRASH_EVERY_S = 3.0


def stamp_header(seq: int, payload: np.ndarray) -> Header:
    """Header carrying the sequence number and the payload checksum."""
    return Header(stamp=Time.now(), frame_id=f"{seq}:{zlib.crc32(payload.data) & 0xFFFFFFFF}")


class Camera(BaseComponent):
    def custom_on_activate(self):
        rng = np.random.default_rng(7)
        self.base = rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8)
        self.seq = 0

    def _execution_step(self):
        frame = np.roll(self.base, self.seq % WIDTH, axis=1)  # a different image every time
        self.publish("camera/rgb", Image.from_numpy(frame, "rgb8", header=stamp_header(self.seq, frame)))
        self.seq += 1
        self.health_status.set_healthy()


class Lidar(BaseComponent):
    def custom_on_activate(self):
        self.angles = np.linspace(-np.pi, np.pi, BEAMS, endpoint=False)
        self.rng = np.random.default_rng(11)
        self.seq = 0

    def _execution_step(self):
        # A 6 x 4 m room seen from its centre, with a little range noise.
        half = np.array([3.0, 2.0])
        with np.errstate(divide="ignore"):
            tx = half[0] / np.abs(np.cos(self.angles))
            ty = half[1] / np.abs(np.sin(self.angles))
        ranges = (np.minimum(tx, ty) + self.rng.normal(0, 0.01, BEAMS)).astype(np.float32)
        scan = LaserScan(
            header=stamp_header(self.seq, ranges), angle_min=-np.pi, angle_max=np.pi - 2 * np.pi / BEAMS,
            angle_increment=2 * np.pi / BEAMS, scan_time=0.05, range_min=0.05, range_max=30.0, ranges=ranges,
        )
        self.publish("scan", scan)
        self.seq += 1
        self.health_status.set_healthy()


class StreamStats:
    """Integrity and latency bookkeeping of one stream."""

    def __init__(self):
        self.received = 0
        self.corrupt = 0
        self.lost = 0
        self.out_of_order = 0
        self.last_seq = None
        self.latency_ms = []

    def check(self, header: Header, payload: np.ndarray) -> None:
        self.received += 1
        self.latency_ms.append((time.time() - header.stamp.to_sec()) * 1e3)
        seq_text, crc_text = header.frame_id.split(":")
        seq = int(seq_text)
        if zlib.crc32(np.ascontiguousarray(payload).data) & 0xFFFFFFFF != int(crc_text):
            self.corrupt += 1
        if self.last_seq is not None:
            if seq > self.last_seq + 1:
                self.lost += seq - self.last_seq - 1
            elif seq <= self.last_seq:
                self.out_of_order += 1
        self.last_seq = seq

    def report(self, name: str) -> str:
        lat = np.array(self.latency_ms) if self.latency_ms else np.array([np.nan])
        return (f"{name:<6} received {self.received:5d}  corrupt {self.corrupt}  lost {self.lost}  "
                f"out-of-order {self.out_of_order}  latency p50 {np.percentile(lat, 50):.2f} ms  "
                f"p99 {np.percentile(lat, 99):.2f} ms  max {lat.max():.2f} ms")


class Checker(BaseComponent):
    def custom_on_configure(self):
        self.stats = {"camera": StreamStats(), "lidar": StreamStats()}

    def _execution_step(self, msg=None, topic=None):
        if isinstance(msg, Image):
            self.stats["camera"].check(msg.header, msg.data)
        elif isinstance(msg, LaserScan):
            self.stats["lidar"].check(msg.header, msg.ranges)
        bad = sum(s.corrupt for s in self.stats.values())
        if bad:
            self.health_status.set_fail_algorithm(algorithm_names=["integrity"], message=f"{bad} corrupt messages")
        else:
            self.health_status.set_healthy()

    def custom_on_shutdown(self):
        print("checker report:", flush=True)
        for name, s in self.stats.items():
            print("  " + s.report(name), flush=True)


class Crasher(BaseComponent):
    def custom_on_activate(self):
        self.started = time.monotonic()

    def _execution_step(self):
        self.health_status.set_healthy()
        if time.monotonic() - self.started > CRASH_EVERY_S:
            os.kill(os.getpid(), signal.SIGKILL)  # a real crash: no clean-up, no goodbye


rgb = Topic(name="camera/rgb", msg_type="Image")
scan = Topic(name="scan", msg_type="LaserScan")

camera = Camera(component_name="camera", outputs=[rgb])
camera.config.loop_rate = 30.0
lidar = Lidar(component_name="lidar", outputs=[scan])
lidar.config.loop_rate = 20.0
checker = Checker(component_name="checker", inputs=[rgb, scan], trigger=[rgb, scan])
crasher = Crasher(component_name="crasher")
crasher.config.loop_rate = 10.0

launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[camera, lidar, checker, crasher], package_name="sensor_demo")
launcher.bringup()
