"""Chaos workload: a group that keeps dying must make the supervisor give up cleanly (exit 3).

Two groups under the root: ``sensors`` (a ticker publishing stamped messages) and ``fragile``
(one worker). The restart intensity is deliberately tight (2 restarts in 5 s), so when the
chaos nemesis kills ``fragile`` faster than that, its group escalates to the root, the root
restarts the group, and once the root's own intensity is breached the whole system stops in
order with exit code 3. Nothing may be left behind.
"""
import zlib

import numpy as np

from emos import BaseComponent, Launcher, Topic
from emos.msgs import Header, LaserScan, Time


class Ticker(BaseComponent):
    def custom_on_activate(self):
        self.seq = 0

    def _execution_step(self):
        ranges = np.full(90, 1.0 + (self.seq % 10) / 10, dtype=np.float32)
        stamp = f"{self.seq}:{zlib.crc32(ranges.data) & 0xFFFFFFFF}"
        self.publish("ticks", LaserScan(header=Header(stamp=Time.now(), frame_id=stamp), ranges=ranges))
        self.seq += 1
        self.health_status.set_healthy()


class Fragile(BaseComponent):
    def _execution_step(self):
        self.health_status.set_healthy()


ticks = Topic(name="ticks", msg_type="LaserScan")
ticker = Ticker(component_name="ticker", outputs=[ticks], trigger=0.05)
fragile = Fragile(component_name="fragile", trigger=0.1)

launcher = Launcher(multi_processing=True, max_restarts=2, max_seconds=5.0, heartbeat_timeout=2.0)
launcher.add_pkg(components=[ticker], package_name="sensors")
launcher.add_pkg(components=[fragile], package_name="fragile")
launcher.bringup()
