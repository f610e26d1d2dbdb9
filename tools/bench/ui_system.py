"""The system ``emos bench ui`` measures: a 640x480 camera at 30 Hz, a 400x400 map at 2 Hz, a
probe subscribing to the camera like any other component, and the UI showing both.

Environment: EMOS_BENCH_UI_PORT, EMOS_BENCH_UI_OUT (the probe writes its latencies there).
"""
import json
import os
import time

import numpy as np

from emos import BaseComponent, Launcher, Topic
from emos.msgs import Image, MapMetaData, OccupancyGrid
from emos.msgs.std import Header, Time

OUT = os.environ["EMOS_BENCH_UI_OUT"]
camera = Topic(name="camera/rgb", msg_type="Image")
grid = Topic(name="map", msg_type="OccupancyGrid")


class Camera(BaseComponent):
    def custom_on_activate(self):
        rng = np.random.default_rng(0)
        # Noise compresses badly: a worst case for the JPEG encoder, as a real scene would be.
        self._frames = [rng.integers(0, 255, (480, 640, 3), dtype=np.uint8) for _ in range(4)]
        self._n = 0

    def _execution_step(self):
        self._n += 1
        frame = self._frames[self._n % 4]
        self.publish(camera, Image.from_numpy(frame, header=Header(stamp=Time.now(), frame_id="camera")))
        self.health_status.set_healthy()


class MapPublisher(BaseComponent):
    def custom_on_activate(self):
        cells = np.zeros((400, 400), np.int8)
        cells[::20, :] = 100
        cells[:, ::25] = 100
        self._cells = cells.reshape(-1)

    def _execution_step(self):
        info = MapMetaData(resolution=0.05, width=400, height=400)
        self.publish(grid, OccupancyGrid(header=Header(stamp=Time.now(), frame_id="map"), info=info, data=self._cells))
        self.health_status.set_healthy()


class Probe(BaseComponent):
    """Another subscriber of the camera: when did each frame reach it."""

    def custom_on_activate(self):
        self._samples = []
        self._last_write = time.monotonic()

    def _execution_step(self, msg=None, topic=None):
        if msg is not None:
            now = time.time_ns()
            self._samples.append((now / 1e9, (now - msg.header.stamp.to_nsec()) / 1e6))
            if time.monotonic() - self._last_write > 0.5:
                self._last_write = time.monotonic()
                with open(OUT + ".tmp", "w") as f:
                    json.dump(self._samples, f)
                os.replace(OUT + ".tmp", OUT)
        self.health_status.set_healthy()


cam = Camera(component_name="camera", outputs=[camera], trigger=1 / 30)
mapper = MapPublisher(component_name="map_server", outputs=[grid], trigger=0.5)
probe = Probe(component_name="probe", inputs=[camera], trigger=camera)

launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[cam, mapper, probe])
launcher.enable_ui(outputs=[camera, grid], port=int(os.environ["EMOS_BENCH_UI_PORT"]))
launcher.bringup()
