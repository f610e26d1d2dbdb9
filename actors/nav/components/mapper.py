"""``Mapper``: graph SLAM as a component (``mapping.slam.GraphSlam``).

Inputs: the laser scan (``sensor_data``) and the odometry (``location``, an Odometry in
``frames.odom``). Outputs: the growing map (``global_map``, an OccupancyGrid on ``/map``,
TRANSIENT_LOCAL, as the MapServer publishes one) and the ``frames.world -> frames.odom``
transform (``tf``), so that the other components keep reading odometry and compose it with the
correction, as with slam_toolbox. Service ``<name>/save_map`` (``Save2dMapToFile``) writes the
current map as map_server YAML + PGM.

A scan becomes a graph node only when the robot moved ``update_min_d`` (m) or turned
``update_min_a`` (rad) since the last node: standing still for an hour adds nothing. The map
is rendered from every node's scan at its optimised pose (log-odds ray casting), at most every
``map_period`` seconds: that rendering costs O(nodes), off the per-scan path, and is what a
loop closure needs (it moves old scans). Bad scans (NaN/inf/zero/max range readings, a beam
count that contradicts the angles) are handled by the SLAM (logged, the node gets the odometry
only) and reported as a failure of the input. ``save_map`` also writes the pose graph
(``NAME.posegraph.npz``: every node's optimised pose and scan) beside the YAML + PGM.

**Localization-only mode** (``mode="localization"``, as slam_toolbox's): the Mapper loads
``map_file`` (its own saved ``*.posegraph.npz`` or a map_server ``*.yaml``), publishes that map
on ``global_map`` once, and localizes every node-worthy scan against it by scan matching
(``mapping.slam.MapLocalizer``): no node, no factor, no hit is ever added, so the map stays the
one loaded. It publishes ``map -> odom`` as in mapping mode. The first scan's pose in the map is
``localize_start`` (default: the saved graph's first node, the map origin for a YAML map); a
``PoseWithCovarianceStamped`` or ``PoseStamped`` on ``initial_pose`` (``/initialpose``) moves it.
"""
from __future__ import annotations

import math
import os
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from attrs import define, field
from attrs.validators import in_

from emos.config.qos import TRANSIENT_LOCAL, QoSConfig
from emos.config.validators import in_range
from emos.core.keyed import AllowedTopic
from emos.errors import ConfigError
from emos.io.topic import Topic
from emos.msgs.geometry import PoseWithCovarianceStamped, Quaternion, TFMessage, Transform, TransformStamped, Vector3
from emos.msgs.std import Header

from ..localization import build_reference_map, compose_pose, relative_pose
from ..mapping.slam import POSEGRAPH_SUFFIX, GraphSlam, MapLocalizer, SlamParams, save_posegraph
from ..maps import OccupancyGridMap, save_map
from .base import NavComponent, NavComponentConfig, rate_field
from .convert import BadInput, grid_msg, pose_of
from .interfaces import SaveMapRequest, SaveMapResponse

__all__ = ["Mapper", "MapperConfig"]


def _slam_params(value: Any) -> SlamParams:
    if isinstance(value, SlamParams):
        return value
    if not isinstance(value, dict):
        raise TypeError(f"MapperConfig.slam_params: expected SlamParams or a dict of its fields, got {type(value).__name__}")
    return SlamParams(**value)


def _start(value: Any) -> tuple[float, float, float] | None:
    if value is None:
        return None
    vals = tuple(float(v) for v in value)
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"MapperConfig.localize_start: expected None or finite (x, y, yaw), got {value!r}")
    return vals


@define(kw_only=True)
class MapperConfig(NavComponentConfig):
    """``slam_params``: a ``SlamParams`` or a dict of its fields. ``update_min_d`` (m) /
    ``update_min_a`` (rad): the motion that makes a scan a node. ``map_period`` (s): how often
    the map is re-rendered and published (0: after every node). ``map_resolution`` (m).
    ``map_file_folder``: where ``save_map`` writes by default.

    ``mode``: ``"mapping"`` (SLAM) or ``"localization"`` (localize against ``map_file``, a saved
    ``*.posegraph.npz`` or a map_server ``*.yaml``, never changing it; module docstring).
    ``localize_start``: the first scan's (x, y, yaw) in that map (None: the graph's first node,
    or the map's origin). ``localize_min_score``: a match scoring less (0..1, the mean
    likelihood of the hits) is not trusted and the pose follows the odometry."""

    loop_rate: float = rate_field(10.0)
    slam_params: SlamParams = field(factory=SlamParams, converter=_slam_params)
    update_min_d: float = field(default=0.2, validator=in_range(min_value=0.0, max_value=100.0))
    update_min_a: float = field(default=0.2, validator=in_range(min_value=0.0, max_value=2 * math.pi))
    map_period: float = field(default=2.0, validator=in_range(min_value=0.0, max_value=3600.0))
    map_resolution: float = field(default=0.05, validator=in_range(min_value=1e-3, max_value=10.0))
    map_file_folder: str = field(default="")
    mode: str = field(default="mapping", validator=in_(("mapping", "localization")))
    map_file: str = field(default="")
    localize_start: tuple[float, float, float] | None = field(default=None, converter=_start)
    localize_min_score: float = field(default=0.3, validator=in_range(min_value=0.0, max_value=1.0))

    def __attrs_post_init__(self) -> None:
        if self.mode == "localization":
            name = os.path.basename(self.map_file)
            if not (name.endswith(POSEGRAPH_SUFFIX) or name.lower().endswith((".yaml", ".yml"))):
                raise ValueError(f"MapperConfig.map_file: mode 'localization' needs a saved pose graph "
                                 f"(*{POSEGRAPH_SUFFIX}) or a map_server YAML (*.yaml), got {self.map_file!r}")


class Mapper(NavComponent):
    """Online graph SLAM (module docstring)."""

    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "sensor_data": AllowedTopic(types=("LaserScan",), default=Topic(name="/scan", msg_type="LaserScan"), required=True),
        "location": AllowedTopic(types=("Odometry",), default=Topic(name="/odom", msg_type="Odometry"), required=True),
        # Localization-only mode: where the robot is in the loaded map (as RViz's 2D Pose Estimate).
        "initial_pose": AllowedTopic(types=("PoseWithCovarianceStamped", "PoseStamped"),
                                     default=Topic(name="/initialpose", msg_type="PoseWithCovarianceStamped")),
    }
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "global_map": AllowedTopic(types=("OccupancyGrid",), default=Topic(name="/map", msg_type="OccupancyGrid", qos_profile=QoSConfig(durability=TRANSIENT_LOCAL)), required=True),
        "tf": AllowedTopic(types=("TFMessage",), default=Topic(name="/tf", msg_type="TFMessage")),
    }
    key_aliases: ClassVar[Mapping[str, str]] = {"map": "global_map"}
    config: MapperConfig

    def __init__(self, component_name: str, config: MapperConfig | None = None, **kwargs: Any) -> None:
        if kwargs.get("run_type") is None and kwargs.get("trigger") is None:
            kwargs["run_type"] = "Event"  # one step per scan, as it arrives
        super().__init__(component_name, config=config, **kwargs)

    @classmethod
    def config_class(cls) -> type[MapperConfig]:
        return MapperConfig

    def custom_on_configure(self) -> None:
        self.default_trigger("sensor_data")
        self.cache_location()  # each scan is added at the odometry of its own stamp
        self._lock = threading.Lock()  # the save service and the steps share the map
        self._slam = GraphSlam(self.config.slam_params, name=f"{self.component_name} ({self.topic_name('sensor_data')})",
                               logger=self.get_logger())
        self._scans: list[tuple[np.ndarray, np.ndarray]] = []
        self._last_node_odom: np.ndarray | None = None
        self._correction = np.zeros(3)
        self._last_scan: Any = None
        self._since_map = math.inf
        self._grid: Any = None
        self._localizer: MapLocalizer | None = None
        self._initial_msg: Any = None
        self._map_sent = False
        if self.config.mode == "localization":
            self._configure_localization()
        self.create_service(f"{self.component_name}/save_map", SaveMapRequest, SaveMapResponse, self._save)

    def _configure_localization(self) -> None:
        cfg = self.config
        path = os.path.expanduser(cfg.map_file)
        try:
            self._localizer = MapLocalizer(path, cfg.slam_params, start=cfg.localize_start,
                                           min_score=cfg.localize_min_score,
                                           name=f"{self.component_name} ({self.topic_name('sensor_data')})",
                                           logger=self.get_logger())
        except (OSError, ValueError) as exc:
            raise ConfigError(f"component {self.component_name!r} (Mapper): cannot load map_file {path!r} for "
                              f"localization-only mode: {exc}") from exc
        src = self._localizer.source
        if isinstance(src, OccupancyGridMap):
            self._grid = src
        else:  # a pose graph: its scans at their saved poses, as mapping mode would have drawn them
            keep = [k for k, r in enumerate(src.ranges) if r.size]
            self._grid = build_reference_map(src.poses[keep], [src.ranges[k] for k in keep],
                                             [src.angles[k] for k in keep], resolution=cfg.map_resolution,
                                             max_range=src.max_range)
        self.get_logger().info("[%s] localization-only mode on %s (map not changed; digest %s)",
                               self.component_name, path, self._localizer.map_digest[:12])

    def _check_initial_pose(self) -> None:
        msg = self.latest("initial_pose")
        if msg is None or msg is self._initial_msg or self._localizer is None:
            return
        self._initial_msg = msg
        try:
            pose = pose_of(msg.pose.pose if isinstance(msg, PoseWithCovarianceStamped) else msg)
            self._localizer.reset(pose)
        except (BadInput, ValueError) as exc:
            self.fail_input("initial_pose", f"{self.topic_name('initial_pose')}: {exc}; keeping the previous estimate")
            return
        self._last_node_odom = None  # the next scan is matched, whatever the motion since the last
        self.get_logger().info("[%s] initial pose (%.2f, %.2f, %.1f deg) from %s", self.component_name,
                               pose[0], pose[1], math.degrees(pose[2]), self.topic_name("initial_pose"))

    def _beams(self, scan: Any) -> tuple[np.ndarray, np.ndarray] | None:
        r = np.asarray(scan.ranges, dtype=np.float64)
        inc, a0 = float(scan.angle_increment), float(scan.angle_min)
        if r.size == 0 or not (math.isfinite(inc) and math.isfinite(a0)) or inc == 0.0:
            self.fail_input("sensor_data", f"{self.topic_name('sensor_data')}: unusable LaserScan ({r.size} ranges, "
                                           f"angle_min={a0}, angle_increment={inc})")
            return None
        expected = int(round((float(scan.angle_max) - a0) / inc)) + 1 if math.isfinite(scan.angle_max) else r.size
        angles = a0 + inc * np.arange(expected if abs(expected - r.size) > 1 else r.size)
        # The mapper's own check names the topic; the SLAM refuses the scan and keeps the node.
        if angles.size != r.size:
            self.fail_input("sensor_data", f"{self.topic_name('sensor_data')}: {r.size} ranges but angle_min.."
                                           f"angle_max / angle_increment give {expected} beams; scan ignored")
        scan_max = float(scan.range_max) if math.isfinite(scan.range_max) and scan.range_max > 0 else math.inf
        r = np.where(r >= scan_max, np.inf, r)  # no echo
        return r, angles

    def _execution_step(self, msg: Any = None, topic: Any = None, **kwargs: Any) -> None:
        with self._lock:
            self._step(msg)

    def _step(self, msg: Any) -> None:
        scan = msg if msg is not None else self.latest("sensor_data")
        if scan is None:
            self.fail_input("sensor_data", f"no scan on {self.topic_name('sensor_data')} yet")
            return
        if scan is self._last_scan:
            return
        self._last_scan = scan
        odom = self.location_at(scan.header.stamp.to_sec())  # reports a missing or bad odometry message by topic
        if odom is None:
            return
        beams = self._beams(scan)
        if beams is None:
            self._publish_tf(scan.header.stamp)
            return
        last = self._last_node_odom
        moved = last is None
        if last is not None:
            d = relative_pose(last, odom)
            moved = math.hypot(d[0], d[1]) >= self.config.update_min_d or abs(d[2]) >= self.config.update_min_a
        if self._localizer is not None:
            self._localize(scan, odom, beams, moved)
            return
        if moved:
            problems = sum(self._slam.problems.values())
            pose = self._slam.add(odom, beams[0], beams[1])
            self._scans.append(beams)
            self._last_node_odom = odom
            # map -> odom: the correction that takes the odometry's pose to the estimate.
            self._correction = compose_pose(pose, relative_pose(odom, np.zeros(3)))
            if sum(self._slam.problems.values()) > problems:
                self.fail_input("sensor_data", f"{self.topic_name('sensor_data')}: bad readings in this scan (see the log)")
        self._publish_tf(scan.header.stamp)
        self._since_map += 1.0 / max(self.config.loop_rate, 1e-6)
        if moved and (self._grid is None or self._since_map >= self.config.map_period):
            self._since_map = 0.0
            self._render()
        if beams[0].size == beams[1].size:
            self.health_status.set_healthy()

    def _localize(self, scan: Any, odom: np.ndarray, beams: tuple[np.ndarray, np.ndarray], moved: bool) -> None:
        loc = self._localizer
        assert loc is not None
        if not self._map_sent and self._grid is not None:
            g = self._grid
            self.publish(self.required_out_topic("global_map"), grid_msg(g.data, g.resolution, g.origin, self.config.frames.world))
            self._map_sent = True
        self._check_initial_pose()
        if self._last_node_odom is None:
            moved = True
        if moved:
            problems = sum(loc.problems.values())
            pose = loc.step(odom, beams[0], beams[1])
            self._last_node_odom = odom
            self._correction = compose_pose(pose, relative_pose(odom, np.zeros(3)))
            if sum(loc.problems.values()) > problems:
                self.fail_input("sensor_data", f"{self.topic_name('sensor_data')}: bad readings in this scan (see the log)")
                self._publish_tf(scan.header.stamp)
                return
            if loc.lost:
                self.fail_algorithm("map_match", f"{loc.unmatched_run} scans in a row do not match the map "
                                                 f"{self.config.map_file}: following the odometry; publish an initial "
                                                 f"pose on {self.topic_name('initial_pose')}")
                self._publish_tf(scan.header.stamp)
                return
        self._publish_tf(scan.header.stamp)
        if beams[0].size == beams[1].size:
            self.health_status.set_healthy()

    @property
    def localizer(self) -> MapLocalizer | None:
        """The localization-only mode's matcher (None in mapping mode), for recipes and tests."""
        return self._localizer

    def _render(self) -> None:
        poses = self._slam.trajectory()
        # Scans the SLAM refused (beam count) are not drawn; every other one from its node.
        keep = [k for k, (r, a) in enumerate(self._scans) if r.size == a.size]
        if not keep:
            return
        self._grid = build_reference_map(poses[keep], [np.where(np.isfinite(self._scans[k][0]), self._scans[k][0], np.inf)
                                                       for k in keep], [self._scans[k][1] for k in keep],
                                         resolution=self.config.map_resolution, max_range=self.config.slam_params.max_range)
        g = self._grid
        self.publish(self.required_out_topic("global_map"), grid_msg(g.data, g.resolution, g.origin, self.config.frames.world))

    def _publish_tf(self, stamp: Any) -> None:
        tf_topic = self.get_out_topic("tf")
        if tf_topic is None:
            return
        frames = self.config.frames
        x, y, yaw = self._correction
        ts = TransformStamped(header=Header(stamp=stamp, frame_id=frames.world), child_frame_id=frames.odom,
                              transform=Transform(translation=Vector3(x=float(x), y=float(y)),
                                                  rotation=Quaternion.from_yaw(float(yaw))))
        self.publish(tf_topic, TFMessage(transforms=[ts]))

    @property
    def trajectory(self) -> np.ndarray:
        """(N, 3) optimised pose of every node, for recipes and tests."""
        return self._slam.trajectory()

    def _save(self, request: SaveMapRequest) -> SaveMapResponse:
        folder = request.file_location or self.config.map_file_folder or "."
        name = request.file_name or "map"
        if "/" in name or name.startswith("."):
            return SaveMapResponse(success=False, message=f"file_name must be a plain name, got {name!r}")
        with self._lock:
            if self._grid is None:
                return SaveMapResponse(success=False, message="no map yet: no scan has been mapped")
            base = Path(os.path.expanduser(folder))
            try:
                path = save_map(self._grid, base / f"{name}.yaml")
                graph = None
                if self._localizer is None:  # mapping mode: the graph too, for localization-only mode
                    p = self.config.slam_params
                    graph = save_posegraph(base / f"{name}{POSEGRAPH_SUFFIX}", self._slam.trajectory(),
                                           [(r, a) if r.size == a.size else (np.zeros(0), np.zeros(0)) for r, a in self._scans],
                                           resolution=p.resolution, sigma=p.sigma, max_range=p.max_range,
                                           min_range=p.min_range)
            except (OSError, ValueError) as exc:
                return SaveMapResponse(success=False, message=f"cannot save the map to {folder}/{name}.yaml: {exc}")
        return SaveMapResponse(success=True, message="saved" if graph is None else f"saved (pose graph: {graph})",
                               path=str(path))
