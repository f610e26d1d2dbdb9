"""``Rplidar``: a component that runs an :class:`RplidarDriver` and publishes ``LaserScan``.

Activation opens the port and starts the scan (a bad, missing or taken port, or a lidar in
Protection Stop, fails activation with an error naming the port, and the status says
SYSTEM_FAILURE with the same words). Each step publishes the scans the driver assembled since
the last step on the output topic (``/scan`` by default) and reports health: HEALTHY while the
stream flows, SYSTEM_FAILURE naming the port while the device is lost (the driver keeps
reconnecting; the stream resumes, and the status turns HEALTHY, when it is back).

Angles follow ROS (counter-clockwise from the lidar's heading, ``angle_min = -pi``); the
RPLIDAR measures clockwise, ``scan.py`` converts. The component is self-contained so that the
robot-plugin API can wrap it later: the driver (``driver.py``) does not know about topics.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from attrs import define, field

from emos.config import validators as V
from emos.config.base import BaseComponentConfig
from emos.core import clock
from emos.core.component import BaseComponent
from emos.io.topic import Topic
from emos.msgs.sensor import LaserScan
from emos.msgs.std import Header

from .driver import RplidarDriver, RplidarError

__all__ = ["RplidarConfig", "Rplidar"]


@define(kw_only=True)
class RplidarConfig(BaseComponentConfig):
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


class Rplidar(BaseComponent):
    """See the module docstring."""

    def __init__(self, *, component_name: str, config: RplidarConfig | None = None,
                 outputs: list[Topic] | None = None, **kwargs: Any) -> None:
        outputs = outputs or [Topic(name="/scan", msg_type="LaserScan")]
        super().__init__(component_name=component_name, outputs=outputs, config=config or RplidarConfig(), **kwargs)
        self.driver: RplidarDriver | None = None
        self.published = 0
        self._device_error = ""

    @classmethod
    def config_class(cls) -> type[BaseComponentConfig]:
        return RplidarConfig

    def custom_on_activate(self) -> None:
        cfg = self.config
        assert isinstance(cfg, RplidarConfig)
        self.driver = RplidarDriver(cfg.port, cfg.baudrate, bins=cfg.bins, range_min=cfg.range_min, range_max=cfg.range_max,
                                    motor_pwm=cfg.motor_pwm, stall_timeout=cfg.stall_timeout)
        try:
            info = self.driver.start()
        except RplidarError as exc:
            self._device_error = str(exc)
            self.driver = None
            raise
        self.get_logger().info("[%s] RPLIDAR on %s: model 0x%02X firmware %s", self.component_name, cfg.port, info.model, info.firmware)

    def custom_on_error(self) -> bool:
        """A failed activation because of the device is a SYSTEM failure (the hardware, not this
        component), reported with the port's name; the component may be activated again."""
        if self._device_error:
            self.health_status.set_fail_system(topic_names=[t.name for t in self.out_topics], message=self._device_error)
            self._device_error = ""
        return True

    def custom_on_deactivate(self) -> None:
        if self.driver is not None:
            self.driver.stop()
            self.driver = None

    def custom_on_shutdown(self) -> None:
        self.custom_on_deactivate()

    def _execution_step(self, **kwargs: Any) -> None:
        driver = self.driver
        if driver is None:
            return
        for scan in driver.get_scans():
            self.publish(self.out_topics[0], self.to_msg(scan))
            self.published += 1
        if driver.error is not None:
            self.health_status.set_fail_system(topic_names=[t.name for t in self.out_topics], message=driver.error)
        else:
            self.health_status.set_healthy()

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
