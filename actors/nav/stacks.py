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

Missions on a stack (``recipes/patrol.py``, ``recipes/dock_on_low_battery.py``) add their parts
through it, wired to its topics: ``stack.waypoint_follower(...)`` (goals to the Planner),
``stack.behaviors(...)`` (Nav2's recovery behaviors) and ``stack.docking_server(...)``. The
recovery behaviors and the docking server drive through the DriveManager on their own command
inputs, above the Controller (``COMMAND_INPUTS``: docking 30, behaviors 20, Controller 10, as
ROS 2's twist_mux ranks its inputs), so their commands never interleave with the Controller's.
``movers=True`` gives the Controller the moving-obstacle handling (the ArcSampler tracking the
scan's clusters and checking each arc, and standing at its end for ``MOVERS_HOLD`` s, against
their positions predicted at constant velocity): it does not drive into a walking person and
avoids stopping where one is heading; a person who turns can still walk into it
(docs/missions.md, "Patrol with recovery behaviors"). ``people_layer=True`` plans on the
``CostToGo`` grid planner with the people layer (``PlannerConfig.people``): ``stack.behaviors()``
then wires the Behaviors' band of where people walked (``PEOPLE_BAND``) to the Planner, and the
routes cross the people's way instead of following it (their passage guard must be enabled).
"""
from __future__ import annotations

import math
import os
from collections.abc import Sequence
from typing import Any

import attrs

from emos.io.topic import Topic

from .components.behaviors import Behaviors, BehaviorsConfig
from .components.controller import Controller
from .components.docking import DockingServer, DockingServerConfig
from .components.drive_manager import CommandInput, DriveManager, DriveManagerConfig
from .components.keys import TopicsKeys
from .components.local_mapper import LocalMapper, LocalMapperConfig
from .components.localizer import Localizer, LocalizerConfig
from .components.map_pose import MapFramePose
from .components.map_server import MapServer, MapServerConfig
from .components.planner import Planner, PlannerConfig
from .components.waypoints import WaypointFollower, WaypointFollowerConfig
from .controllers import ControllersID
from .local_map import MapConfig
from .robot import RobotConfig, RobotFrames

__all__ = ["BEHAVIORS_COMMAND", "COMMAND_INPUTS", "CONTROLLER_COMMAND", "DOCKING_COMMAND", "LOCALIZER_FILTER", "MOVERS_HOLD",
           "MOVERS_MAX_SPEED", "NavigationStack", "PEOPLE_BAND", "point_navigation_stack"]

MOVERS_MAX_SPEED = 0.5  # m/s: the top speed of the movers=True Controller (a house with people in it)
MOVERS_HOLD = 2.5  # s: how long the robot must be able to stand at an arc's end out of every predicted mover's way
CONTROLLER_COMMAND = Topic(name="/control", msg_type="Twist")
BEHAVIORS_COMMAND = Topic(name="/control/behaviors", msg_type="Twist")
DOCKING_COMMAND = Topic(name="/control/docking", msg_type="Twist")
#: where people walked: the Behaviors' band, the Planner's people layer
PEOPLE_BAND = Topic(name="/people_band", msg_type="OccupancyGrid")
#: The DriveManager's prioritised inputs for a stack with recovery behaviors and docking: a
#: docking approach over a recovery behavior over the Controller. The Controller's timeout is
#: the DriveManager's cmd_timeout; the others release the robot 0.5 s after their last command.
COMMAND_INPUTS = (CommandInput(topic=CONTROLLER_COMMAND.name, priority=10, timeout=0.3),
                  CommandInput(topic=BEHAVIORS_COMMAND.name, priority=20, timeout=0.5),
                  CommandInput(topic=DOCKING_COMMAND.name, priority=30, timeout=0.5))

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
    scan: Topic = attrs.field(factory=lambda: Topic(name="/scan", msg_type="LaserScan"))

    def __attrs_post_init__(self) -> None:
        if not self.driver.config.static_map:  # the DriveManager's movers on the map's walls are not people
            self.driver.config.static_map = self.static_map_file

    @property
    def static_map_file(self) -> str:
        """The stack's map file for telling movers from walls (``controllers.movers.WallFilter``):
        when the stack's pose is in the map's frame (localized, or odometry in the world frame)
        and the map is a YAML file here (the MapServer reports a missing one when it starts); else ''."""
        map_file = self.map_server.config.map_file_path
        in_map_frame = self.localizer is not None or self.frames.odom == self.frames.world
        return map_file if in_map_frame and map_file.endswith((".yaml", ".yml")) and os.path.isfile(map_file) else ""

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

    def use_zones(self, keepout_mask: str = "", speed_mask: str = "") -> None:
        """Keepout and speed zones (mask YAML files in the map's frame, ``emos map zones``) for the
        whole stack, as Nav2 puts its filters on both costmaps: the Planner plans round keepout
        zones; the Controller takes their edges as obstacles and caps its speed in speed zones; the
        DriveManager, whatever input drives, stops a command whose swept footprint would enter a
        keepout zone and caps speed too. Each mask is loaded and checked here."""
        if keepout_mask:
            self.planner.config.costmap.keepout_mask = keepout_mask
            self.controller.config.keepout_mask = keepout_mask
            self.driver.config.keepout_mask = keepout_mask
        if speed_mask:
            self.planner.config.costmap.speed_mask = speed_mask
            self.controller.config.speed_mask = speed_mask
            self.driver.config.speed_mask = speed_mask

    # -- mission parts, wired to the stack --------------------------------------------------------
    def _command_input(self, topic: Topic, who: str) -> Topic:
        """``topic`` if the DriveManager has it among its command inputs; else a clear error."""
        wired = [t.name for t in self.driver.get_in_topics("command")]
        if topic.name not in wired or not self.driver.config.command_inputs:
            raise ValueError(f"{who} drives through the DriveManager's command input {topic.name}, which this stack's "
                             f"DriveManager does not have (its inputs: {', '.join(wired)}): build the stack with "
                             f"point_navigation_stack(..., command_inputs=COMMAND_INPUTS)")
        return topic

    def waypoint_follower(self, name: str = "waypoints", config: WaypointFollowerConfig | None = None, **kwargs: Any) -> WaypointFollower:
        """A ``WaypointFollower`` sending its goals to the Planner and watching it (``kwargs``:
        ``waypoint_task``, ``tasks``)."""
        follower = WaypointFollower(name, config=config, **kwargs)
        follower.inputs(location=self.location, reached_end=self.planner.get_out_topic(TopicsKeys.REACHED_END),
                        planner_status=Topic(name=f"{self.planner.component_name}/status", msg_type="ComponentStatus"))
        follower.outputs(goal_point=self.planner.get_in_topic(TopicsKeys.GOAL_POINT))
        return follower

    def behaviors(self, name: str = "behaviors", config: BehaviorsConfig | None = None) -> Behaviors:
        """Nav2's recovery behaviors on the stack's scan, pose and local grid (what the scan no
        longer sees, behind the robot), driving on ``BEHAVIORS_COMMAND``. They get the stack's map
        as ``static_map`` (movers on its walls are not people) unless the config names one, when
        the stack's pose is in the map's frame (localized, or odometry in the world frame) and the
        map is a YAML file here (the MapServer reports a missing one when it starts)."""
        config = config or BehaviorsConfig(local_mapper=self.local_mapper.component_name)
        if not config.static_map and self.static_map_file:
            config = attrs.evolve(config, static_map=self.static_map_file)
        behaviors = Behaviors(name, config=config)
        behaviors.inputs(sensor_data=self.scan, location=self.location, local_map=self.local_mapper.get_out_topic("local_map"))
        behaviors.outputs(robot_command=self._command_input(BEHAVIORS_COMMAND, f"Behaviors {name!r}"))
        if self.planner.config.people.enabled:
            if not behaviors.config.passage_guard.enabled:
                raise ValueError(f"Behaviors {name!r}: the Planner plans with the people layer, which the passage guard's "
                                 f"band feeds: give BehaviorsConfig(passage_guard=PassageGuardConfig(enabled=True))")
            behaviors.outputs(people=PEOPLE_BAND)
            self.planner.inputs(people=PEOPLE_BAND)
        return behaviors

    def docking_server(self, name: str = "docking", config: DockingServerConfig | None = None) -> DockingServer:
        """Nav2's docking server on the stack's scan and pose, driving on ``DOCKING_COMMAND``."""
        docking = DockingServer(name, config=config)
        docking.inputs(sensor_data=self.scan, location=self.location)
        docking.outputs(robot_command=self._command_input(DOCKING_COMMAND, f"DockingServer {name!r}"))
        return docking


def point_navigation_stack(robot: RobotConfig, frames: RobotFrames, map_file: str, *, odom: Topic, command: Topic,
                           scan: Topic | None = None, localize: bool = False, tf: Topic | None = None,
                           initial_pose: Sequence[float] = (0.0, 0.0, 0.0), seed: int = 0,
                           command_inputs: Sequence[CommandInput] = (), movers: bool = False,
                           people_layer: bool = False) -> NavigationStack:
    """The main job's point-navigation stack (see the module doc) on ``map_file``.

    ``odom`` is the base's odometry; ``command`` the velocity topic the DriveManager publishes;
    ``scan`` the laser scan of the LocalMapper, Controller and DriveManager (None: their default,
    ``/scan``). ``localize`` adds the Localizer, started at ``initial_pose`` (x, y, yaw) with
    ``seed``, publishing ``map -> odom`` on ``tf`` (default ``/tf``); ``frames.odom`` must then
    name the odometry's own frame. ``command_inputs``: the DriveManager's prioritised inputs
    (``COMMAND_INPUTS`` for a stack with recovery behaviors or docking; empty: the Controller's one
    input). ``movers``: the Controller tracks moving obstacles in the scan and yields to them (see
    the module doc). ``people_layer``: plan on ``CostToGo`` with the people layer (the module doc)."""
    if localize and frames.odom == frames.world:
        raise ValueError(f"point_navigation_stack: localize=True needs the odometry in its own frame, but frames.odom "
                         f"is {frames.odom!r}, the same as frames.world (give RobotFrames(odom='odom'))")
    # movers: the ArcSampler's own planner (BARN's pairing): CostToGo's paths keep to the middle of
    # corridors and doorways, where the arcs' clearance scoring wants them.
    planner_config = PlannerConfig(loop_rate=1.0)
    if movers or people_layer:
        planner_config.planner_id = "CostToGo"
    if people_layer:
        planner_config.people = attrs.evolve(planner_config.people, enabled=True)
    planner = Planner(component_name="planner", config=planner_config)
    planner.run_type = "Timed"
    controller = Controller(component_name="controller")
    controller.algorithm = ControllersID.PURE_PURSUIT
    controller.direct_sensor = False  # obstacles from the LocalMapper's grid
    if movers:
        from .controllers import ArcSamplerConfig
        from .controllers.arcs import ArcConfig
        from .controllers.movers import MoverConfig, PredictionConfig

        # The ArcSampler with the moving-obstacle tracker: each arc is checked against where the
        # tracked movers will be, and so is standing at its end for MOVERS_HOLD s (1 s, the
        # tracker's default, let the robot stop where a person arrived 1.5 s later), with reverse
        # arcs to back out of a mover's way; the static check stays on the LocalMapper's grid, the
        # movers are tracked in the scan (in beam order). Indoors among people: 0.5 m/s at most.
        controller.algorithm = ControllersID.ARC_SAMPLER
        controller.algorithms_config = ArcSamplerConfig(
            movers=MoverConfig(prediction=PredictionConfig(hold=MOVERS_HOLD)),
            arcs=ArcConfig(max_speed=min(MOVERS_MAX_SPEED, robot.ctrl_vx_limits.max_vel), max_turn=robot.ctrl_omega_limits.max_vel))
        controller.inputs(sensor_data=scan if scan is not None else Topic(name="/scan", msg_type="LaserScan"))
    driver = DriveManager(
        component_name="drive_manager",
        config=DriveManagerConfig(critical_zone_distance=0.05, critical_zone_angle=90.0, slowdown_zone_distance=0.3,
                                  command_inputs=tuple(command_inputs)),
    )
    driver.outputs(robot_command=command)
    local_mapper = LocalMapper(component_name="mapper",
                               config=LocalMapperConfig(map_params=MapConfig(width=3.0, height=3.0, resolution=0.05)))
    map_server = MapServer(component_name="global_map_server", config=MapServerConfig(map_file_path=map_file, grid_resolution=0.5))
    if scan is not None:
        for component in (controller, driver, local_mapper):
            component.inputs(sensor_data=scan)
    scan_topic = scan if scan is not None else Topic(name="/scan", msg_type="LaserScan")
    if not localize:
        return NavigationStack(robot, frames, map_server, planner, controller, driver, local_mapper, location=odom, scan=scan_topic)

    tf = tf if tf is not None else Topic(name="/tf", msg_type="TFMessage")
    location = Topic(name="/odometry/localized", msg_type="Odometry")
    localizer = Localizer(component_name="localizer", config=LocalizerConfig(
        set_initial_pose=True, initial_pose=tuple(initial_pose), seed=seed, filter_params=dict(LOCALIZER_FILTER)))
    localizer.inputs(location=odom, map=map_server.get_out_topic(TopicsKeys.GLOBAL_MAP))
    localizer.outputs(tf=tf)
    map_pose = MapFramePose(odom=odom, tf=tf, location=location, frames=frames)
    return NavigationStack(robot, frames, map_server, planner, controller, driver, local_mapper, location=location,
                           localizer=localizer, map_pose=map_pose, scan=scan_topic)
