"""The system ``emos bench record`` measures: the sensor demo's camera and a latency probe.

The probe appends ``receive time, latency ms`` for every frame to ``$EMOS_BENCH_LATENCY_FILE``.
"""
import os
import time

import numpy as np

from emos import BaseComponent, Launcher, Topic
from emos.msgs import Header, Image, Time

OUT = os.environ.get("EMOS_BENCH_LATENCY_FILE", "/dev/null")


class Camera(BaseComponent):
    def custom_on_activate(self):
        self.base = np.random.default_rng(7).integers(0, 256, (480, 640, 3), dtype=np.uint8)
        self.seq = 0

    def _execution_step(self):
        frame = np.roll(self.base, self.seq % 640, axis=1)
        self.publish("camera/rgb", Image.from_numpy(frame, "rgb8", header=Header(stamp=Time.now(), frame_id=str(self.seq))))
        self.seq += 1
        self.health_status.set_healthy()


class Probe(BaseComponent):
    def custom_on_activate(self):
        self.out = open(OUT, "a", buffering=1)  # noqa: SIM115 - open while active, closed in custom_on_deactivate

    def _execution_step(self, msg=None, topic=None):
        now = time.time_ns()
        self.out.write(f"{now / 1e9:.6f} {(now - msg.header.stamp.to_nsec()) / 1e6:.4f}\n")
        self.health_status.set_healthy()

    def custom_on_deactivate(self):
        self.out.close()


rgb = Topic(name="camera/rgb", msg_type="Image")
camera = Camera(component_name="camera", outputs=[rgb])
camera.config.loop_rate = 30.0
probe = Probe(component_name="probe", inputs=[rgb], trigger=rgb)
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[camera, probe], package_name="bench")
launcher.bringup()
