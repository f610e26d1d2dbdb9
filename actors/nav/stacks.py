"""Ready-made navigation stacks: the components a recipe would otherwise wire by hand each time.

    stack = point_navigation_stack(my_robot, frames, map_file, odom=odom_topic, command=cmd_topic)
    stack.launch(launcher)           # the stack's packages, its location wiring, robot and frames
    goal = stack.planner.get_in_topic(TopicsKeys.GOAL_POINT)

The point-navigation stack is the main job's (recipes/point_navigation.py) and the one its
ROS 2 and hardware variants drive: ``MapServer`` (the map file, planned on a 0.5 m grid),
``Planner`` (timed, once a second), ``Controller`` (Pure Pursuit on the ``LocalMapper``'s 3 x 3 m
grid, not on the raw scan), ``DriveManager`` (a 5 cm critical zone over 90 degrees, a 30 cm
slow-down zone) publishing on ``command``. With ``localize=True`` it also runs the ``Localizer``
(Monte Carlo localization on the map, ``map -> odom`` on ``tf``) and ``MapFramePose`` (the
pose in the map frame on ``/odometry/localized``), and that pose is the ``location`` the
navigation components read; otherwise the odometry is the location (its frame is the map's).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import attrs

from emos.io.topic import Topic

from .components.controller import Controller
from .components.drive_manager import DriveManager, DriveManagerConfig
from .components.keys import TopicsKeys
from .components.local_mapper import LocalMapper, LocalMapperConfig
from .components.localizer import Localizer, LocalizerConfig
from .components.map_pose import MapFramePose
from .components.map_server import MapServer, MapServerConfig
from .components.planner import Planner, PlannerConfig
from .controllers import ControllersID
from .local_map import MapConfig
from .robot import RobotConfig, RobotFrames

__all__ = ["NavigationStack", "point_navigation_stack", "LOCALIZER_FILTER"]

# The Localizer's particle filter in the main job: little odometry noise (a wheel + gyro base),
# 300-1500 particles, an update every 5 cm or 0.05 rad, and a tight start round the spawn.
LOCALIZER_FILTER: dict[str, Any] = {
    "alpha1": 0.05, "alpha2": 0.05, "alpha3": 0.05, "alpha4": 0.05, "min_particles": 300,
    "max_particles": 1500, "update_min_d": 0.05, "update_min_a": 0.05, "sigma_hit": 0.1,
    "max_beams": 90, "initial_cov_xy": 0.01, "initial_cov_yaw": math.radians(5) ** 2}


@attrs.define(eq=False)
class NavigationStack:
    """The components of a navigation stack and the topics a mission needs from it."""

    robot: RobotConfig
    frames: RobotFrames
    map_server: MapServer
    planner: Planner
    controller: Controller
    driver: DriveManager
    local_mapper: LocalMapper
    location: Topic  # what the navigation components take as the robot's pose
    localizer: Localizer | None = None
    map_pose: MapFramePose | None = None

    @property
    def navigation(self) -> list[Any]:
        """The Kompass components, in the order the launcher starts them."""
        return [self.map_server, self.controller, self.planner, self.driver, self.local_mapper]

    @property
    def localization(self) -> list[Any]:
        return [c for c in (self.localizer, self.map_pose) if c is not None]

    @property
    def component_names(self) -> list[str]:
        """Every component of the stack by name (e.g. to watch their ``<name>/status``)."""
        names = ["global_map_server", "planner", "controller", "drive_manager", "mapper"]
        return names + [c.component_name for c in self.localization]

    def launch(self, launcher: Any, multiprocessing: bool = True) -> None:
        """Add the stack to ``launcher``: the navigation package, then (localized) a
        ``localization`` package; the location wiring; the robot and frames of every component."""
        launcher.kompass(components=self.navigation, multiprocessing=multiprocessing)
        if self.localization:
            launcher.add_pkg(components=self.localization, package_name="localization", multiprocessing=multiprocessing)
        # Wired one by one: the launcher-wide launcher.inputs(location=...) would also rewire
        # the Localizer, whose location is the raw odometry it corrects.
        for component in (self.controller, self.planner, self.driver, self.local_mapper):
            component.inputs(location=self.location)
        launcher.robot = self.robot
        launcher.frames = self.frames


def point_navigation_stack(robot: RobotConfig, frames: RobotFrames, map_file: str, *, odom: Topic, command: Topic,
                           scan: Topic | None = None, localize: bool = False, tf: Topic | None = None,
                           initial_pose: Sequence[float] = (0.0, 0.0, 0.0), seed: int = 0) -> NavigationStack:
    """The main job's point-navigation stack (see the module doc) on ``map_file``.

    ``odom`` is the base's odometry; ``command`` the velocity topic the DriveManager publishes;
    ``scan`` the laser scan of the LocalMapper, Controller and DriveManager (None: their default,
    ``/scan``). ``localize`` adds the Localizer, started at ``initial_pose`` (x, y, yaw) with
    ``seed``, publishing ``map -> odom`` on ``tf`` (default ``/tf``); ``frames.odom`` must then
    name the odometry's own frame."""
    if localize and frames.odom == frames.world:
        raise ValueError(f"point_navigation_stack: localize=True needs the odometry in its own frame, but frames.odom "
                         f"is {frames.odom!r}, the same as frames.world (give RobotFrames(odom='odom'))")
    planner = Planner(component_name="planner", config=PlannerConfig(loop_rate=1.0))
    planner.run_type = "Timed"
    controller = Controller(component_name="controller")
    controller.algorithm = ControllersID.PURE_PURSUIT
    controller.direct_sensor = False  # obstacles from the LocalMapper's grid
    driver = DriveManager(
        component_name="drive_manager",
        config=DriveManagerConfig(critical_zone_distance=0.05, critical_zone_angle=90.0, slowdown_zone_distance=0.3),
    )
    driver.outputs(robot_command=command)
    local_mapper = LocalMapper(component_name="mapper",
                               config=LocalMapperConfig(map_params=MapConfig(width=3.0, height=3.0, resolution=0.05)))
    map_server = MapServer(component_name="global_map_server", config=MapServerConfig(map_file_path=map_file, grid_resolution=0.5))
    if scan is not None:
        for component in (controller, driver, local_mapper):
            component.inputs(sensor_data=scan)
    if not localize:
        return NavigationStack(robot, frames, map_server, planner, controller, driver, local_mapper, location=odom)

    tf = tf if tf is not None else Topic(name="/tf", msg_type="TFMessage")
    location = Topic(name="/odometry/localized", msg_type="Odometry")
    localizer = Localizer(component_name="localizer", config=LocalizerConfig(
        set_initial_pose=True, initial_pose=tuple(initial_pose), seed=seed, filter_params=dict(LOCALIZER_FILTER)))
    localizer.inputs(location=odom, map=map_server.get_out_topic(TopicsKeys.GLOBAL_MAP))
    localizer.outputs(tf=tf)
    map_pose = MapFramePose(odom=odom, tf=tf, location=location, frames=frames)
    return NavigationStack(robot, frames, map_server, planner, controller, driver, local_mapper, location=location,
                           localizer=localizer, map_pose=map_pose)
