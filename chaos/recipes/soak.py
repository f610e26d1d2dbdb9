"""Chaos workload for kill soaks: stamped sensor streams whose components may be killed
hundreds of times in one run.

The same shapes as the sensor demo (a 640x480 RGB camera at 30 Hz, a 720-beam scan at 20 Hz,
a consumer of both), but with a restart intensity loose enough that a chaos run can SIGKILL
components every quarter of a second for minutes: what is under test is that each kill is
recovered and that nothing (segments, processes, directories, zombies) accumulates.
Payloads are stamped ``<seq>:<crc32>`` so the chaos topic observer checks every message.
"""
import zlib

import numpy as np

from emos import BaseComponent, Launcher, Topic
from emos.msgs import Header, Image, LaserScan, Time


def _stamp(seq, payload):
    return Header(stamp=Time.now(), frame_id=f"{seq}:{zlib.crc32(np.ascontiguousarray(payload).data) & 0xFFFFFFFF}")


class Camera(BaseComponent):
    def custom_on_activate(self):
        self.base = np.random.default_rng(7).integers(0, 256, (480, 640, 3), dtype=np.uint8)
        self.seq = 0

    def _execution_step(self):
        frame = np.roll(self.base, self.seq % 640, axis=1)
        self.publish("camera/rgb", Image.from_numpy(frame, "rgb8", header=_stamp(self.seq, frame)))
        self.seq += 1
        self.health_status.set_healthy()


class Lidar(BaseComponent):
    def custom_on_activate(self):
        self.seq = 0

    def _execution_step(self):
        ranges = (2.0 + np.sin(np.linspace(0, 6.28, 720) + self.seq / 10)).astype(np.float32)
        self.publish("scan", LaserScan(header=_stamp(self.seq, ranges), ranges=ranges, range_max=30.0))
        self.seq += 1
        self.health_status.set_healthy()


class Consumer(BaseComponent):
    def _execution_step(self, msg=None, topic=None):
        self.health_status.set_healthy()


camera_topic = Topic(name="camera/rgb", msg_type="Image")
scan_topic = Topic(name="scan", msg_type="LaserScan")
camera = Camera(component_name="camera", outputs=[camera_topic], trigger=1 / 30)
lidar = Lidar(component_name="lidar", outputs=[scan_topic], trigger=1 / 20)
consumer = Consumer(component_name="consumer", inputs=[camera_topic, scan_topic], trigger=[camera_topic, scan_topic])

# 1,000 restarts a second is "never give up": escalation has its own scenario.
launcher = Launcher(multi_processing=True, max_restarts=1000, max_seconds=1.0)
launcher.add_pkg(components=[camera, lidar, consumer], package_name="soak")
launcher.bringup()
