"""``Localizer``: where the robot is on the map, by Monte Carlo localization (the AMCL family).

Inputs: the laser scan (``sensor_data``), the odometry (``location``, an Odometry in
``frames.odom``), the map (``map``, an OccupancyGrid, TRANSIENT_LOCAL as the MapServer publishes
it) and an initial pose (``initial_pose``: ``/initialpose``, a PoseWithCovarianceStamped as RViz
and Nav2 send it, or a PoseStamped as a UI map click sends it). Outputs: the estimate
(``pose``, PoseWithCovarianceStamped on ``/amcl_pose``), the particle cloud (``particles``,
PoseArray on ``/particle_cloud``) and the ``frames.world -> frames.odom`` transform (``tf``,
TFMessage on ``/tf``), so the other components keep reading odometry and compose it with the
correction, as with Nav2. Service ``<name>/global_localization`` (Trigger): forget the pose and
spread the particles over the free space of the map.

Each scan steps the filter (``localization.ParticleFilter``; parameters in ``filter_params``,
Nav2's names and defaults). Bad input never stops it: a scan with NaN/inf/zero/max-range
readings uses its valid beams; a scan without any, or whose beam count does not match its
angles, or a map without obstacles, leaves the particles to the odometry (the covariance grows);
an odometry jump spreads them (see the filter); an initial pose outside the map is refused.
Each is a rate-limited log line naming the topic and a SYSTEM failure on it, until good data
returns. Without an initial pose (``set_initial_pose``, ``/initialpose`` or the service) the
Localizer publishes nothing and says so.

A Localizer restarted within a run (killed, hung) resumes from its last ``map -> odom`` (kept in
``<run dir>/<name>.localizer.json``, at most once a second) composed with the odometry it reads
then, instead of the configured initial pose: the robot has moved since it started, and
the odometry kept counting while the Localizer was down (``resume_on_restart``, on by default;
Nav2's AMCL keeps its last pose in its parameters for the same reason).
"""
from __future__ import annotations

import json
import math
import os
import threading
import time
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from attrs import define, field

from emos.config.qos import TRANSIENT_LOCAL, QoSConfig
from emos.config.validators import in_range
from emos.core.keyed import AllowedTopic
from emos.io.topic import Topic
from emos.msgs.geometry import (
    Point,
    Pose,
    PoseArray,
    PoseStamped,
    PoseWithCovariance,
    PoseWithCovarianceStamped,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from emos.msgs.srv import TriggerRequest, TriggerResponse
from emos.msgs.std import Header

from ..localization import AmclParams, ParticleFilter, compose_pose, relative_pose
from .base import NavComponent, NavComponentConfig, rate_field
from .convert import BadInput, grid_map_of, pose_of

__all__ = ["Localizer", "LocalizerConfig"]


def _params(value: Any) -> AmclParams:
    return AmclParams.of(value, "LocalizerConfig.filter_params")


def _pose3(value: Any) -> tuple[float, float, float]:
    vals = tuple(float(v) for v in value)
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"expected finite (x, y, yaw), got {value!r}")
    return vals


@define(kw_only=True)
class LocalizerConfig(NavComponentConfig):
    """``filter_params``: an ``AmclParams`` or a dict of its fields (Nav2 AMCL names: alpha1..4,
    min_particles, max_particles, pf_err, pf_z, update_min_d, update_min_a, resample_interval,
    recovery_alpha_slow/fast, z_hit, z_rand, sigma_hit, laser_likelihood_max_dist,
    laser_max_range, laser_min_range, max_beams, ...). ``set_initial_pose`` / ``initial_pose``
    (x, y, yaw): start there (Nav2's names). ``sensor_pose``: (x, y, yaw) of the scanner on the
    robot. ``seed``: the filter's random seed (None: fresh). ``max_published_particles``: the
    particle cloud message holds at most this many (an even subsample)."""

    loop_rate: float = rate_field(10.0)
    filter_params: AmclParams = field(factory=AmclParams, converter=_params)
    set_initial_pose: bool = field(default=False)
    initial_pose: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), converter=_pose3)
    sensor_pose: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), converter=_pose3)
    seed: int | None = field(default=None)
    max_published_particles: int = field(default=1000, validator=in_range(min_value=0, max_value=1_000_000))
    resume_on_restart: bool = field(default=True)


def _pose_msg(x: float, y: float, yaw: float) -> Pose:
    return Pose(position=Point(x=float(x), y=float(y)), orientation=Quaternion.from_yaw(float(yaw)))


class Localizer(NavComponent):
    """Monte Carlo localization on a map (module docstring)."""

    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "sensor_data": AllowedTopic(types=("LaserScan",), default=Topic(name="/scan", msg_type="LaserScan"), required=True),
        "location": AllowedTopic(types=("Odometry",), default=Topic(name="/odom", msg_type="Odometry"), required=True),
        "map": AllowedTopic(types=("OccupancyGrid",), default=Topic(name="/map", msg_type="OccupancyGrid", qos_profile=QoSConfig(durability=TRANSIENT_LOCAL)), required=True),
        "initial_pose": AllowedTopic(types=("PoseWithCovarianceStamped", "PoseStamped"), default=Topic(name="/initialpose", msg_type="PoseWithCovarianceStamped")),
    }
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "pose": AllowedTopic(types=("PoseWithCovarianceStamped",), default=Topic(name="/amcl_pose", msg_type="PoseWithCovarianceStamped"), required=True),
        "particles": AllowedTopic(types=("PoseArray",), default=Topic(name="/particle_cloud", msg_type="PoseArray")),
        "tf": AllowedTopic(types=("TFMessage",), default=Topic(name="/tf", msg_type="TFMessage")),
    }
    config: LocalizerConfig

    def __init__(self, component_name: str, config: LocalizerConfig | None = None, **kwargs: Any) -> None:
        # Event-driven by default: one filter step per scan, as it arrives (Timed also works:
        # each step takes the newest scan, once).
        if kwargs.get("run_type") is None and kwargs.get("trigger") is None:
            kwargs["run_type"] = "Event"
        super().__init__(component_name, config=config, **kwargs)

    @classmethod
    def config_class(cls) -> type[LocalizerConfig]:
        return LocalizerConfig

    def custom_on_configure(self) -> None:
        self.default_trigger("sensor_data")
        self.cache_location()  # each scan is matched from the odometry of its own stamp
        self._lock = threading.Lock()  # the service and the steps share the filter
        self._filter: ParticleFilter | None = None
        self._map_msg: Any = None
        self._initial_msg: Any = None
        self._global_pending = False
        self._correction = np.zeros(3)  # map -> odom as (x, y, yaw)
        self._has_pose = False
        self._last_scan: Any = None
        self._problems = 0
        self._saved_at = -math.inf
        self._resume = self._read_resume() if self.config.resume_on_restart else None
        self.create_service(f"{self.component_name}/global_localization", TriggerRequest, TriggerResponse, self._global_service)

    # -- problems, reported once per interval and as a failure of the input -------------------------------
    def _problem(self, key: str, message: str) -> None:
        topic_key = {"jump": "location", "beams": "sensor_data"}.get(key, key)
        self._problems += 1  # this step is not a healthy one, whatever else goes right in it
        self.fail_input(topic_key, f"{self.topic_name(topic_key)}: {message}")

    # -- the map, the initial pose, global localization -----------------------------------------------------
    def _refresh_map(self) -> bool:
        msg = self.latest("map")
        if msg is None:
            self.fail_input("map", f"no map on {self.topic_name('map')} yet")
            return False
        if msg is self._map_msg:
            return True
        try:
            grid = grid_map_of(msg)
            if grid.data.size != int(msg.info.width) * int(msg.info.height):
                raise BadInput(f"map: {msg.info.width}x{msg.info.height} grid with {grid.data.size} cells")
        except (BadInput, ValueError) as exc:
            self.fail_input("map", f"{self.topic_name('map')}: {exc}")
            return self._filter is not None  # keep localizing on the previous map
        self._map_msg = msg
        if self._filter is None:
            self._filter = ParticleFilter(self.config.filter_params, grid, sensor_pose=self.config.sensor_pose,
                                          seed=self.config.seed, on_problem=self._problem)
            if self.config.set_initial_pose and self._resume is None:
                self._initialize(np.array(self.config.initial_pose), None, "initial_pose (config)")
        else:
            self._filter.set_map(grid)
        if not self._filter.field.has_obstacles:
            self.fail_input("map", f"{self.topic_name('map')}: the map has no occupied cell (unknown or free only): "
                                   "scans cannot be matched, the pose follows the odometry alone")
        if self._global_pending:
            self._global_pending = False
            self._global()
        return True

    def _initialize(self, pose: np.ndarray, cov: np.ndarray | None, source: str) -> None:
        assert self._filter is not None  # called once a map made the filter
        try:
            self._filter.initialize(pose, cov)
        except ValueError as exc:
            self._problems += 1
            self.fail_input("initial_pose", f"{source}: {exc}; keeping the previous estimate")
            return
        self._has_pose = True
        self.get_logger().info("[%s] initial pose (%.2f, %.2f, %.1f deg) from %s", self.component_name,
                               pose[0], pose[1], math.degrees(pose[2]), source)

    def _check_initial_pose(self) -> None:
        msg = self.latest("initial_pose")
        if msg is None or msg is self._initial_msg or self._filter is None:
            return
        self._initial_msg = msg
        name = self.topic_name("initial_pose")
        cov: np.ndarray | None = None
        try:
            if isinstance(msg, PoseWithCovarianceStamped):
                pose = pose_of(msg.pose.pose)
                c = np.asarray(msg.pose.covariance, dtype=np.float64).reshape(6, 6)
                given = c[np.ix_([0, 1, 5], [0, 1, 5])]
                if not np.all(np.isfinite(given)) or np.any(np.diag(given) < 0):
                    raise BadInput(f"covariance is not a finite, non-negative one: diag {np.diag(given).tolist()}")
                cov = given if np.any(given) else None  # an all-zero covariance: the default spread
            else:
                pose, cov = pose_of(msg), None
        except BadInput as exc:
            self._problems += 1
            self.fail_input("initial_pose", f"{name}: {exc}")
            return
        self._initialize(pose, cov, name)

    # -- a restart resumes from the last map -> odom (module docstring) ---------------------------------------
    def _resume_path(self) -> Any:
        run_dir = getattr(getattr(self.node, "ctx", None), "run_dir", None)
        return None if run_dir is None else run_dir / f"{self.component_name}.localizer.json"

    def _read_resume(self) -> tuple[np.ndarray, np.ndarray] | None:
        path = self._resume_path()
        if path is None:
            return None
        try:
            state = json.loads(path.read_text())
            correction = np.array(state["correction"], dtype=np.float64).reshape(3)
            cov = np.array(state["covariance"], dtype=np.float64).reshape(3, 3)
            if not (np.all(np.isfinite(correction)) and np.all(np.isfinite(cov)) and np.all(np.diag(cov) >= 0)):
                raise ValueError("non-finite or negative values")
        except FileNotFoundError:
            return None  # the first start of this run
        except (OSError, ValueError, KeyError, TypeError) as exc:
            self.get_logger().warning("[%s] cannot resume from %s (%s): starting as configured", self.component_name, path, exc)
            return None
        return correction, cov

    def _save_resume(self) -> None:
        path, now = self._resume_path(), time.monotonic()
        if path is None or now - self._saved_at < 1.0 or self._filter is None:
            return
        self._saved_at = now
        state = {"correction": self._correction.tolist(), "covariance": self._filter.covariance.tolist()}
        tmp = path.with_name(path.name + ".tmp")
        try:
            tmp.write_text(json.dumps(state))
            os.replace(tmp, path)
        except OSError as exc:
            self._report.warning("resume", "[%s] cannot save the estimate to %s: %s", self.component_name, path, exc,
                                 logger=self.get_logger())

    def _resume_from(self, odom: np.ndarray) -> None:
        assert self._resume is not None
        correction, cov = self._resume
        self._resume = None
        # The covariance of the last estimate, at least the default spread of an initial pose
        # (the odometry ran unchecked while this Localizer was down).
        p = self.config.filter_params
        cov = cov + np.diag([p.initial_cov_xy, p.initial_cov_xy, p.initial_cov_yaw]) * 0.1
        self._correction = correction
        self._initialize(compose_pose(correction, odom), cov, "the last map -> odom of this run (restarted)")

    def _global(self) -> tuple[bool, str]:
        if self._filter is None:
            self._global_pending = True
            return True, "global localization starts when the map arrives"
        try:
            self._filter.global_localization()
        except ValueError as exc:
            self.fail_algorithm("global_localization", str(exc))
            return False, str(exc)
        self._has_pose = True
        return True, f"{self._filter.particle_count} particles spread over the free space"

    def _global_service(self, request: TriggerRequest) -> TriggerResponse:
        with self._lock:
            ok, message = self._global()
        return TriggerResponse(success=ok, message=message)

    # -- one scan ---------------------------------------------------------------------------------------------
    def _scan_beams(self, scan: Any) -> tuple[np.ndarray, np.ndarray] | None:
        """(ranges, angles) of a scan; None (reported) when its beam count contradicts its angles."""
        r = np.asarray(scan.ranges, dtype=np.float64)
        inc, a0, a1 = float(scan.angle_increment), float(scan.angle_min), float(scan.angle_max)
        name = self.topic_name("sensor_data")
        if r.size == 0 or not all(math.isfinite(v) for v in (inc, a0, a1)) or inc == 0.0:
            self.fail_input("sensor_data", f"{name}: unusable LaserScan ({r.size} ranges, angle_min={a0}, "
                                           f"angle_max={a1}, angle_increment={inc})")
            return None
        expected = int(round((a1 - a0) / inc)) + 1
        if abs(expected - r.size) > 1:
            self.fail_input("sensor_data", f"{name}: {r.size} ranges but angle_min..angle_max / angle_increment "
                                           f"give {expected} beams; scan ignored")
            return None
        return r, a0 + inc * np.arange(r.size)

    def _execution_step(self, msg: Any = None, topic: Any = None, **kwargs: Any) -> None:
        with self._lock:
            self._step(msg)

    def _step(self, msg: Any) -> None:
        self._problems = 0
        scan = msg if msg is not None else self.latest("sensor_data")
        if not self._refresh_map():
            return
        assert self._filter is not None  # made by _refresh_map
        self._check_initial_pose()
        if self._resume is not None and not self._has_pose:
            odom_msg = self.latest("location")
            try:
                if odom_msg is not None:
                    self._resume_from(pose_of(odom_msg))
            except BadInput:
                pass  # reported below, where the odometry is read for the step
        if not self._has_pose:
            self.fail_algorithm("initial_pose", f"no initial pose: publish one on {self.topic_name('initial_pose')} "
                                                f"or call {self.component_name}/global_localization")
            return
        if scan is None:
            self.fail_input("sensor_data", f"no scan on {self.topic_name('sensor_data')} yet")
            return
        if scan is self._last_scan:
            return  # Timed: no new scan since the last step
        self._last_scan = scan
        odom = self.location_at(scan.header.stamp.to_sec())  # reports a missing or bad odometry message by topic
        if odom is None:
            return
        beams = self._scan_beams(scan)
        healthy = beams is not None and self._filter.field.has_obstacles
        r, a = beams if beams is not None else (np.zeros(0), np.zeros(0))
        if not self._filter.field.has_obstacles:
            r, a = np.zeros(0), np.zeros(0)  # nothing to match against: the odometry alone
        scan_max = float(scan.range_max) if math.isfinite(scan.range_max) and scan.range_max > 0 else math.inf
        scan_min = float(scan.range_min) if math.isfinite(scan.range_min) and scan.range_min >= 0 else 0.0
        updated = self._filter.update(odom, r, a, scan_max=scan_max, scan_min=scan_min, force=not healthy)
        if updated:
            # map -> odom: the correction that takes the odometry's pose to the estimate.
            self._correction = compose_pose(self._filter.estimate, relative_pose(odom, np.zeros(3)))
            healthy = healthy and self._filter.beams_used > 0
            if self.config.resume_on_restart:
                self._save_resume()
        self._publish(odom, scan.header.stamp, updated)
        if healthy and updated and not self._problems:
            self.health_status.set_healthy()

    def _publish(self, odom: np.ndarray, stamp: Any, updated: bool) -> None:
        assert self._filter is not None
        frames = self.config.frames
        est = compose_pose(self._correction, odom)  # the estimate now, odometry since the update included
        cov6 = np.zeros(36)
        c = self._filter.covariance
        for i, a in enumerate((0, 1, 5)):
            for j, b in enumerate((0, 1, 5)):
                cov6[a * 6 + b] = c[i, j]
        out = PoseWithCovarianceStamped(header=Header(stamp=stamp, frame_id=frames.world),
                                        pose=PoseWithCovariance(pose=_pose_msg(*est), covariance=cov6))
        self.publish(self.required_out_topic("pose"), out)
        tf_topic = self.get_out_topic("tf")
        if tf_topic is not None:
            x, y, yaw = self._correction
            ts = TransformStamped(header=Header(stamp=stamp, frame_id=frames.world), child_frame_id=frames.odom,
                                  transform=Transform(translation=Vector3(x=float(x), y=float(y)),
                                                      rotation=Quaternion.from_yaw(float(yaw))))
            self.publish(tf_topic, TFMessage(transforms=[ts]))
        cloud = self.get_out_topic("particles")
        if cloud is not None and updated and self.config.max_published_particles > 0:
            parts = self._filter.particles
            step = max(1, math.ceil(len(parts) / self.config.max_published_particles))
            self.publish(cloud, PoseArray(header=Header(stamp=stamp, frame_id=frames.world),
                                          poses=[_pose_msg(*p) for p in parts[::step]]))

    @property
    def estimate(self) -> PoseStamped | None:
        """The latest estimate (None before an initial pose), for recipes and tests."""
        if self._filter is None or not self._has_pose:
            return None
        from .convert import pose_stamped

        x, y, yaw = self._filter.estimate
        return pose_stamped(float(x), float(y), float(yaw), self.config.frames.world)
