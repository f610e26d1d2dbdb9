"""``Rplidar``: an RPLIDAR A1/A2 as a robot plugin publishing ``LaserScan`` (key ``scan``, the
Simulator's key for the same topic).

Built on :class:`emos.actors.hardware.plugin.RobotPlugin` with a driver session
(:class:`~emos.actors.hardware.plugin.SessionTransport` over :class:`RplidarDriver`, which owns the
serial port because the device's start-up is a request/response flow of its own: health, info,
motor, scan). Activation opens the port and starts the scan (a bad, missing or taken port, or a
lidar in Protection Stop, fails activation with an error naming the port, and the status says
SYSTEM_FAILURE with the same words). Each poll (``loop_rate``) publishes the scans the driver
assembled since the last one and reports health: HEALTHY while the stream flows, SYSTEM_FAILURE
naming the port while the device is lost (the driver keeps reconnecting; the stream resumes,
and the status turns HEALTHY, when it is back).

Angles follow ROS (counter-clockwise from the lidar's heading, ``angle_min = -pi``); the
RPLIDAR measures clockwise, ``scan.py`` converts. Action: ``restart_scan`` (stop, then the whole
start-up again); ``lidar_stats`` (scans, corrupt scans, dropped bytes, reconnects).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from attrs import define, field

from emos.config import validators as V
from emos.core import clock
from emos.msgs.sensor import LaserScan
from emos.msgs.std import Header

from ..plugin import Feedback, PluginConfig, RobotPlugin, SessionTransport, plugin_action
from .driver import RplidarDriver, RplidarError

__all__ = ["RplidarConfig", "Rplidar", "RplidarError"]


@define(kw_only=True)
class RplidarConfig(PluginConfig):
    """``port``: the serial device; ``bins``: beams per published scan (360 for an A1's ~1 deg);
    ranges outside [range_min, range_max] are published as inf (no return)."""

    loop_rate: float = field(default=40.0, validator=V.finite_positive)  # > 10 Hz scans: none waits long
    port: str = field(default="/dev/ttyUSB0", validator=V.non_empty_str)
    baudrate: int = field(default=115200, converter=int, validator=V.int_at_least(1200))
    frame_id: str = field(default="laser", validator=V.non_empty_str)
    bins: int = field(default=360, converter=int, validator=V.int_at_least(8))
    range_min: float = field(default=0.15, converter=float, validator=V.finite_non_negative)
    range_max: float = field(default=12.0, converter=float, validator=V.finite_positive)
    motor_pwm: int = field(default=660, converter=int, validator=V.number(ge=0, le=1023, integer=True))
    stall_timeout: float = field(default=2.0, converter=float, validator=V.finite_positive)


class Rplidar(RobotPlugin):
    """See the module docstring."""

    plugin_name = "rplidar"
    description = "Slamtec RPLIDAR A1/A2 2D lidar (serial protocol, standard scan)"
    feedback: ClassVar[Mapping[str, Feedback]] = {"scan": Feedback(msg_type="LaserScan", topic="/scan", help="one revolution, counter-clockwise from -pi")}

    def __init__(self, component_name: str = "lidar", config: RplidarConfig | None = None, **kwargs: Any) -> None:
        super().__init__(component_name, config or RplidarConfig(), **kwargs)
        self.config: RplidarConfig
        self.driver: RplidarDriver | None = None
        self.published = 0

    @classmethod
    def config_class(cls) -> type[RplidarConfig]:
        return RplidarConfig

    def make_transports(self) -> Mapping[str, SessionTransport]:
        cfg = self.config
        driver = RplidarDriver(cfg.port, cfg.baudrate, bins=cfg.bins, range_min=cfg.range_min, range_max=cfg.range_max,
                               motor_pwm=cfg.motor_pwm, stall_timeout=cfg.stall_timeout)

        def start() -> None:
            info = driver.start()
            self.driver = driver
            self.get_logger().info("[%s] RPLIDAR on %s: model 0x%02X firmware %s", self.component_name, cfg.port,
                                   info.model, info.firmware)

        def stop() -> None:
            driver.stop()
            self.driver = None

        return {"serial": SessionTransport("RPLIDAR", cfg.port, start=start, stop=stop, error=lambda: driver.error)}

    def on_poll(self) -> None:
        driver = self.driver
        if driver is None:
            return
        for scan in driver.get_scans():
            self.emit("scan", self.to_msg(scan))
            self.published += 1

    @plugin_action("stop the scan and run the whole start-up again (health, info, motor, scan)")
    def restart_scan(self) -> bool:
        transport = self.transports.get("serial")
        if transport is None:
            return False
        transport.close()
        transport.open()
        return True

    @plugin_action("counters: scans, corrupt scans, dropped bytes, reconnects")
    def lidar_stats(self) -> dict:
        d = self.driver
        if d is None:
            return {"running": False}
        return {"running": True, "port": d.port, "scans": d.scans, "corrupt_scans": d.corrupt_scans,
                "bytes_dropped": d.bytes_dropped, "reconnects": d.reconnects, "error": d.error}

    def to_msg(self, scan) -> LaserScan:
        cfg = self.config
        assert isinstance(cfg, RplidarConfig)
        n = len(scan.ranges)
        return LaserScan(
            header=Header(stamp=clock.stamp(), frame_id=cfg.frame_id),
            angle_min=float(scan.angle_min), angle_max=float(scan.angle_min + scan.angle_increment * (n - 1)),
            angle_increment=float(scan.angle_increment),
            # beams are re-binned from the clockwise sweep: per-beam timing is not kept
            time_increment=0.0, scan_time=float(scan.scan_time) if math.isfinite(scan.scan_time) else 0.0,
            range_min=cfg.range_min, range_max=cfg.range_max,
            ranges=np.asarray(scan.ranges, dtype=np.float32), intensities=np.asarray(scan.intensities, dtype=np.float32))
