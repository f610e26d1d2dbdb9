"""``LocalMapper``: the ego-centric occupancy grid around the robot, from its laser scans."""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from attrs import define, field
from attrs.validators import in_

from emos.config.base import ComponentRunType
from emos.config.qos import TRANSIENT_LOCAL, QoSConfig
from emos.config.validators import in_range
from emos.core import clock
from emos.core.keyed import AllowedTopic
from emos.io.topic import Topic
from emos.msgs import Odometry
from emos.msgs.srv import TriggerRequest, TriggerResponse

from ..local_map import LocalMapper as GridBuilder
from ..local_map import MapConfig
from ..mapping import EvidenceConfig, MemoryMapper
from ..mapping.scan_matching import compose
from .base import NavComponent, NavComponentConfig, rate_field
from .convert import BadInput, grid_msg, localized_odometry, pose_stamped, scan_of

__all__ = ["LocalMapper", "LocalMapperConfig", "memory_of"]


def _map_config(value: Any) -> MapConfig:
    if isinstance(value, MapConfig):
        return value
    if isinstance(value, dict):
        return MapConfig(**value)
    raise TypeError(f"LocalMapperConfig.map_params: expected a MapConfig, got {type(value).__name__}")


def _bounds(value: Any) -> tuple[float, float, float, float] | None:
    if value is None:
        return None
    vals = tuple(float(v) for v in value)
    if len(vals) != 4 or not all(math.isfinite(v) for v in vals) or not (vals[2] > vals[0] and vals[3] > vals[1]):
        raise ValueError(f"mapping_bounds: expected finite (xmin, ymin, xmax, ymax) with max > min, got {value!r}")
    return vals


def _sensor_pose(value: Any) -> tuple[float, float, float]:
    vals = tuple(float(v) for v in value)
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"sensor_pose: expected finite (x, y, yaw) of the sensor on the robot, got {value!r}")
    return vals


def _memory_decay(value: Any) -> EvidenceConfig | None:
    return EvidenceConfig.of(value, "LocalMapperConfig.memory_decay")


@define(kw_only=True)
class LocalMapperConfig(NavComponentConfig):
    """``map_params``: window size and resolution around the robot. ``keep_memory``: cells the
    latest scan does not see keep what earlier scans saw (rolled with the robot's odometry), so
    obstacles that leave a narrow field of view are not forgotten. ``sensor_pose``: (x, y, yaw)
    of the scanner on the robot.

    Mapping mode (``mapping_bounds`` = (xmin, ymin, xmax, ymax) of a world window): every scan
    is also added to an obstacle memory over that window, at the odometry pose corrected by
    matching the scan against the memory (``scan_matching``; a match is adopted when it raises
    the scan's mean likelihood by more than ``match_margin`` over the odometry's guess). Every scan
    is matched, but the never-forgetting memory takes a scan in only once the corrected pose has
    moved ``map_update_distance`` m or turned ``map_update_angle`` rad since the last one it took
    in (Hector SLAM's ``map_update_distance_thresh`` / ``map_update_angle_thresh``): a memory
    that takes in every scan at 50 scans/s takes each in at a pose off by the millimetre of
    wheel slip no match can see, smears the obstacles along the motion and lets the estimate
    follow the odometry's drift (``MemoryMapper``; 0 and 0 take in every scan). The memory is published on the
    ``mapping`` output (an OccupancyGrid in ``frames.world``, every ``map_publish_period`` s;
    a Planner can take it as its map) and the corrected pose on ``localized_pose``. The memory
    never forgets by default (static worlds); ``memory_decay`` (an ``EvidenceConfig`` or a dict
    of its fields) makes it forget by evidence (cells later scans see through are released:
    a moving obstacle's trail goes, walls stay), for worlds where obstacles move.

    ``local_map_frame``: ``"robot"`` (default) publishes the grid in ``frames.robot_base``, as
    seen from the robot at its scan; ``"world"`` publishes the same grid in ``frames.world``,
    its origin placed at the pose of its scan (the corrected pose in mapping mode, else the
    odometry's), like a rolling-window costmap in ``odom``. A reader then places the obstacles
    by the grid's own origin, not by its own latest pose, which may be a scan older or newer
    than the grid (the Controller does: it plans from its current pose). Needs ``location``."""

    loop_rate: float = rate_field(10.0)
    map_params: MapConfig = field(factory=MapConfig, converter=_map_config)
    keep_memory: bool = field(default=False)
    sensor_pose: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), converter=_sensor_pose)
    mapping_bounds: tuple[float, float, float, float] | None = field(default=None, converter=_bounds)
    scan_matching: bool = field(default=True)
    match_margin: float = field(default=0.01, validator=in_range(min_value=0.0, max_value=1.0))
    map_update_distance: float = field(default=0.2, validator=in_range(min_value=0.0, max_value=100.0))
    map_update_angle: float = field(default=0.2, validator=in_range(min_value=0.0, max_value=math.pi))
    mapping_resolution: float = field(default=0.05, validator=in_range(min_value=1e-3, max_value=10.0))
    map_publish_period: float = field(default=1.0, validator=in_range(min_value=0.0, max_value=3600.0))
    #: s: a scan older than this is a SYSTEM failure naming the topic, and no grid is published
    #: (the Controller must not drive on an old picture). Timed: checked at every step; Event:
    #: by a watchdog at ``loop_rate`` once the first scan arrived. Not checked with
    #: ``use_sim_time`` (lockstep: a wall-clock age means nothing while the simulator waits).
    sensor_timeout: float = field(default=1.0, validator=in_range(min_value=1e-3, max_value=1e3))
    memory_decay: EvidenceConfig | None = field(default=None, converter=_memory_decay)
    local_map_frame: str = field(default="robot", validator=in_(("robot", "world")))

    def __attrs_post_init__(self) -> None:
        if self.memory_decay is not None and self.mapping_bounds is None:
            raise ValueError("LocalMapperConfig.memory_decay: the memory exists in mapping mode only; "
                             "set mapping_bounds too (or leave memory_decay None)")


def memory_of(cfg: LocalMapperConfig) -> MemoryMapper | None:
    """The obstacle memory (with scan matching) a LocalMapper of this config keeps, or None
    without ``mapping_bounds``; also what an offline replay of its scans builds."""
    if cfg.mapping_bounds is None:
        return None
    decay = cfg.memory_decay
    forgetting: dict[str, Any] = {} if decay is None else {"evidence_cap": decay.cap, "free_range": decay.free_range}
    return MemoryMapper(cfg.mapping_bounds, cfg.mapping_resolution, cfg.sensor_pose, cfg.scan_matching,
                        match_margin=cfg.match_margin, update_distance=cfg.map_update_distance,
                        update_angle=cfg.map_update_angle, **forgetting)


class LocalMapper(NavComponent):
    """Publishes the grid (robot frame, ``frames.robot_base``) on ``local_map``.

    Timed (default, ``loop_rate``) or Event: with ``run_type = "Event"`` every scan is mapped as
    it arrives (the low-latency choice; the trigger defaults to the ``sensor_data`` topic).
    """

    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "sensor_data": AllowedTopic(types=("LaserScan",), default=Topic(name="/scan", msg_type="LaserScan"), required=True),
        "location": AllowedTopic(types=("Odometry", "PoseStamped", "Pose"), default=Topic(name="/odom", msg_type="Odometry")),
    }
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "local_map": AllowedTopic(types=("OccupancyGrid",), default=Topic(name="/local_map/occupancy_layer", msg_type="OccupancyGrid"), required=True),
        "mapping": AllowedTopic(types=("OccupancyGrid",), default=Topic(name="/local_map/memory", msg_type="OccupancyGrid", qos_profile=QoSConfig(durability=TRANSIENT_LOCAL))),
        "localized_pose": AllowedTopic(types=("PoseStamped", "Odometry"), default=Topic(name="/local_map/pose", msg_type="PoseStamped")),
    }
    config: LocalMapperConfig

    @classmethod
    def config_class(cls) -> type[LocalMapperConfig]:
        return LocalMapperConfig

    def custom_on_configure(self) -> None:
        out, loc = self.get_out_topic("localized_pose"), self.get_in_topic("location")
        if out is not None and out.msg_type is Odometry and (loc is None or loc.msg_type is not Odometry):
            raise ValueError(f"{self.component_name}: localized_pose {out.name} is an Odometry (the corrected pose with the "
                             f"measured twist), so the location input must be an Odometry topic too; got "
                             f"{'none' if loc is None else f'{loc.name} ({loc.msg_type.__name__})'}")
        self.default_trigger("sensor_data")
        self.cache_location()  # each scan is placed where the robot was when it was taken
        self._builder = GridBuilder(self.config.map_params, sensor_pose=self.config.sensor_pose, keep_memory=self.config.keep_memory)
        self._memory = memory_of(self.config)
        self._memory_published = -math.inf
        # Nav2's clear_entirely_local_costmap: a recovery behavior (Behaviors.clear_costmaps)
        # empties the grid, so obstacles that have gone stop blocking the robot.
        self.create_service(f"{self.component_name}/clear_entirely_local_costmap", TriggerRequest, TriggerResponse,
                            lambda request: TriggerResponse(success=self.clear_costmap(), message="local grid cleared"))

    def clear_costmap(self) -> bool:
        """Forget every obstacle of the local grid (the obstacle memory of mapping mode is kept:
        it is the map, not a costmap); the next scan starts it again. An event action too."""
        self._builder = GridBuilder(self.config.map_params, sensor_pose=self.config.sensor_pose, keep_memory=self.config.keep_memory)
        self.get_logger().info("[%s] local grid cleared", self.component_name)
        return True

    def custom_on_activate(self) -> None:
        if self.run_type == ComponentRunType.EVENT and not self.config.use_sim_time:
            self.create_timer(1.0 / self.config.loop_rate, self._watchdog)

    def _scan_is_stale(self) -> bool:
        """A SYSTEM failure when the last scan is older than ``sensor_timeout`` (a dead scanner)."""
        age = self.age_of("sensor_data")
        if self.config.use_sim_time or age is None or age <= self.config.sensor_timeout:
            return False
        self.fail_input("sensor_data", f"{self.topic_name('sensor_data')} is stale: last scan {age:.2f} s ago "
                                       f"(limit {self.config.sensor_timeout:g} s)")
        return True

    def _watchdog(self) -> None:
        if self._scan_is_stale():
            self.node.publish_status()  # at once: events and fallbacks act on it

    def _execution_step(self, msg: Any = None, topic: Any = None, **kwargs: Any) -> None:
        scan_msg = msg if msg is not None else self.latest("sensor_data")
        if scan_msg is None:
            self.fail_input("sensor_data", f"no scan on {self.topic_name('sensor_data')} yet")
            return
        if msg is None and self._scan_is_stale():
            return
        try:
            scan = scan_of(scan_msg)
        except BadInput as exc:
            self.fail_input("sensor_data", str(exc))
            return
        pose, loc = None, None
        in_world = self.config.local_map_frame == "world"
        if self.config.keep_memory or self._memory is not None or in_world:
            loc = self.latest("location")
            if loc is None:
                why = "a world-frame local_map" if in_world and not self.config.keep_memory else "keep_memory"
                self.fail_input("location", f"{why} needs odometry on {self.topic_name('location')}")
                return
            pose = self.location_at(scan_msg.header.stamp.to_sec())
            if pose is None:
                return  # reported by location_at
        grid = self._builder.update(scan, pose)
        o = self._builder.origin
        origin: tuple[float, float, float] | np.ndarray
        if in_world:
            assert pose is not None  # read from the location above, which a world-frame map needs
            # Placed where the robot was at the scan, in the frame of the pose the robot is
            # located by: the memory's corrected pose when there is one, else the odometry's.
            at = self._update_memory(scan, pose, loc, scan_msg.header.stamp) if self._memory is not None else pose
            origin, frame = compose(at, (o[0], o[1], 0.0)), self.config.frames.world
        else:
            origin, frame = (o[0], o[1], 0.0), self.config.frames.robot_base
        out = grid_msg(grid, self.config.map_params.resolution, origin, frame)
        out.header.stamp = scan_msg.header.stamp  # the map is as old as the scan it shows
        self.publish(self.required_out_topic("local_map"), out)
        if self._memory is not None and not in_world:
            self._update_memory(scan, pose, loc, scan_msg.header.stamp)
        self.health_status.set_healthy()

    def _update_memory(self, scan: Any, odom_pose: Any, location: Any, stamp: Any) -> Any:
        """Add the scan to the memory, publish the corrected pose (and the memory when due);
        return the corrected pose."""
        assert self._memory is not None  # called only in mapping mode, which has a memory
        corrected = self._memory.update(scan, odom_pose)
        world = self.config.frames.world
        out = self.get_out_topic("localized_pose")
        if out is not None:
            # Stamped with its scan: the pose is where the robot was when the scan was taken (and
            # under a simulator the stamp is on the simulated clock, not the machine's).
            pose = pose_stamped(corrected[0], corrected[1], corrected[2], world, stamp=stamp)
            # As an Odometry with the measured twist of the odometry it corrects: a controller's
            # response model needs what the base does, not what it was told.
            msg = localized_odometry(pose, location, self.config.frames.robot_base) if out.msg_type is Odometry else pose
            self.publish(out, msg)
        now = clock.now()  # simulated seconds under a simulator: the map's age must not follow the machine's speed
        out = self.get_out_topic("mapping")
        if out is not None and now - self._memory_published >= self.config.map_publish_period:
            grid = self._memory.grid
            memory = grid_msg(self._memory.occupancy(), grid.resolution, (grid.origin[0], grid.origin[1], 0.0), world)
            memory.header.stamp = stamp  # as of the scan it last took in
            self.publish(out, memory)
            self._memory_published = now
        return corrected
