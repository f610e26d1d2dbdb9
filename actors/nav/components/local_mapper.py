"""``LocalMapper``: the ego-centric occupancy grid around the robot, from its laser scans."""
from __future__ import annotations

import math
from typing import Any

from attrs import define, field

from emos.config.base import ComponentRunType
from emos.core.keyed import AllowedTopic
from emos.io.topic import Topic

from ..local_map import LocalMapper as GridBuilder
from ..local_map import MapConfig
from .base import NavComponent, NavComponentConfig, rate_field
from .convert import BadInput, grid_msg, pose_of, scan_of

__all__ = ["LocalMapper", "LocalMapperConfig"]


def _map_config(value: Any) -> MapConfig:
    if isinstance(value, MapConfig):
        return value
    if isinstance(value, dict):
        return MapConfig(**value)
    raise TypeError(f"LocalMapperConfig.map_params: expected a MapConfig, got {type(value).__name__}")


def _sensor_pose(value: Any) -> tuple[float, float, float]:
    vals = tuple(float(v) for v in value)
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"sensor_pose: expected finite (x, y, yaw) of the sensor on the robot, got {value!r}")
    return vals  # type: ignore[return-value]


@define(kw_only=True)
class LocalMapperConfig(NavComponentConfig):
    """``map_params``: window size and resolution around the robot. ``keep_memory``: cells the
    latest scan does not see keep what earlier scans saw (rolled with the robot's odometry), so
    obstacles that leave a narrow field of view are not forgotten. ``sensor_pose``: (x, y, yaw)
    of the scanner on the robot."""

    loop_rate: float = rate_field(10.0)
    map_params: MapConfig = field(factory=MapConfig, converter=_map_config)
    keep_memory: bool = field(default=False)
    sensor_pose: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), converter=_sensor_pose)


class LocalMapper(NavComponent):
    """Publishes the grid (robot frame, ``frames.robot_base``) on ``local_map``.

    Timed (default, ``loop_rate``) or Event: with ``run_type = "Event"`` every scan is mapped as
    it arrives (the low-latency choice; the trigger defaults to the ``sensor_data`` topic).
    """

    allowed_inputs = {
        "sensor_data": AllowedTopic(types=("LaserScan",), default=Topic(name="/scan", msg_type="LaserScan"), required=True),
        "location": AllowedTopic(types=("Odometry", "PoseStamped", "Pose"), default=Topic(name="/odom", msg_type="Odometry")),
    }
    allowed_outputs = {
        "local_map": AllowedTopic(types=("OccupancyGrid",), default=Topic(name="/local_map/occupancy_layer", msg_type="OccupancyGrid"), required=True),
    }
    config: LocalMapperConfig

    @classmethod
    def config_class(cls) -> type[LocalMapperConfig]:
        return LocalMapperConfig

    def custom_on_configure(self) -> None:
        if self.run_type == ComponentRunType.EVENT and not self._trigger:
            self._trigger = [self.get_in_topic("sensor_data")]
        self._builder = GridBuilder(self.config.map_params, sensor_pose=self.config.sensor_pose, keep_memory=self.config.keep_memory)
        self._last_scan_stamp = -1

    def _execution_step(self, msg: Any = None, topic: Any = None) -> None:
        scan_msg = msg if msg is not None else self.latest("sensor_data")
        if scan_msg is None:
            self.fail_input("sensor_data", f"no scan on {self.topic_name('sensor_data')} yet")
            return
        try:
            scan = scan_of(scan_msg)
        except BadInput as exc:
            self.fail_input("sensor_data", str(exc))
            return
        pose = None
        if self.config.keep_memory:
            loc = self.latest("location")
            if loc is None:
                self.fail_input("location", f"keep_memory needs odometry on {self.topic_name('location')}")
                return
            try:
                pose = pose_of(loc)
            except BadInput as exc:
                self.fail_input("location", str(exc))
                return
        grid = self._builder.update(scan, pose)
        o = self._builder.origin
        out = grid_msg(grid, self.config.map_params.resolution, (o[0], o[1], 0.0), self.config.frames.robot_base)
        out.header.stamp = scan_msg.header.stamp  # the map is as old as the scan it shows
        self.publish(self.get_out_topic("local_map"), out)
        self.health_status.set_healthy()
