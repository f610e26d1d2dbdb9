"""Cross-component healing: the spec's cross-component-events recipe, on the real navigation stack.

    emos run recipes/events_and_resilience/cross_component_events.py --duration 60

One component's status makes a *different* component act:

A. The ``Controller`` reports ALGORITHM_FAILURE (stuck: the way ahead is blocked): the
   ``DriveManager`` runs its ``move_to_unblock`` maneuver (forward, backward or a rotation,
   whichever the scan allows; ``keep_event_delay=60``: at most once a minute).
B. The ``LocalMapper`` stops being HEALTHY (its scanner went silent): the ``Controller`` switches
   to the raw scan (``update_parameter(use_direct_sensor=True)``, ``handle_once=True``).
C. A point clicked on ``/clicked_point`` (``header.stamp.sec > 0``, the spec's ``OnGreater``):
   log it, and send the ``Planner`` (an ActionServer) a ``PlanPath`` goal made from the point by
   an event parser; the robot drives there.

What is real: Planner, Controller (DWA), LocalMapper, DriveManager, the Monitor running the
events, and the ``Simulator`` (pybullet, headless) standing in for the robot: the demo house,
the robot in its first room, its odometry, lidar and map.

What is stood in, and how the faults are made:
* ``Operator`` is the person clicking in RViz: once the robot's odometry and the Planner are up,
  it publishes one ``PointStamped`` goal (``GOAL``), 2.2 m ahead of the robot;
* the block: a wall across the room (``BLOCKING_WALL``, a Simulator obstacle, so it is not on
  the map the Planner plans on) stands 0.9 m ahead of the robot; the plan goes through it, the
  robot drives up to it, stops, and the Controller reports that it makes no progress;
* the mapper's sensor dropout: the LocalMapper reads its scan through ``ScanDriver``, which
  relays the Simulator's lidar (``/scan``) to ``/mapper/scan`` and goes silent ``DROPOUT_AFTER``
  seconds after it started relaying (a crashed driver); the LocalMapper reports its input stale
  (SYSTEM failure) and the Controller, switched to direct mode, reads ``/scan`` itself.

Differences from the spec's code: imports; the Controller's ``progress_timeout=3`` (see the
comment there); the Simulator publishes the map the Planner needs (the spec's robot has one from
elsewhere); the mapper runs as ``Event`` (each scan as it arrives) so that it does not report
"no scan yet" while the Simulator starts, which would fire event B before any fault;
``multiprocessing=True`` (errata: ``multi_processing`` is the Launcher's argument); ``Twist``
commands (no ROS distro here). The robot configuration, the events, the actions and the goal
parser are the spec's.
"""
import time

import numpy as np

from emos import Action, BaseComponent, ComponentStatus, Event, Launcher, Topic
from emos import events as event
from emos.actions import ComponentActions, LogInfo, update_parameter
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.components import Controller, ControllerConfig, DriveManager, LocalMapper, Planner, PlannerConfig
from emos.actors.nav.components.interfaces import PathTrackingError, PlanPath
from emos.actors.sim import Simulator, SimulatorConfig, Wall
from emos.config.base import BaseComponentConfig
from emos.msgs import Header, LaserScan, Point, PointStamped, Pose, Time

ROBOT_SPAWN = (1.0, 2.0, 0.0)  # x, y, yaw in the house's first room, facing +x
GOAL = (3.2, 2.0)  # what the operator clicks
BLOCKING_WALL = Wall(start=(1.9, 0.3), end=(1.9, 3.85))  # across the whole room, not on the map
DROPOUT_AFTER = 6.0  # s of relaying before the mapper's scan driver goes silent

# --- Robot Configuration ---
my_robot = RobotConfig(
    model_type=RobotType.DIFFERENTIAL_DRIVE,
    geometry_type=RobotGeometry.Type.CYLINDER,
    geometry_params=np.array([0.1, 0.3]),
    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.2, max_acc=1.5, max_decel=2.5),
    ctrl_omega_limits=AngularCtrlLimits(max_vel=0.4, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
)

# --- Components ---
planner = Planner(component_name="planner", config=PlannerConfig(loop_rate=1.0))
planner.run_type = "ActionServer"
# progress_timeout: DWA stops short of an obstacle (no collision-free command moves it on) rather
# than fail; the progress checker turns "no progress along the plan for 3 s" into the
# ALGORITHM_FAILURE the spec's controller reports when it is stuck.
controller = Controller(component_name="controller", config=ControllerConfig(progress_timeout=3.0))
controller.direct_sensor = False
mapper = LocalMapper(component_name="mapper")
driver = DriveManager(component_name="drive_manager")
cmd_msg_type = "Twist"  # the spec picks TwistStamped for ROS 2 jazzy and later; no ROS distro here
driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type=cmd_msg_type))

# --- Cross-Component Events ---
# 1. Controller stuck -> DriveManager unblocks
event_controller_fail = Event(
    controller.status_topic.msg.status == ComponentStatus.STATUS_FAILURE_ALGORITHM_LEVEL,
    keep_event_delay=60.0,
)
unblock_action = Action(method=driver.move_to_unblock)

# 2. Mapper down -> Controller switches to direct sensor mode
event_mapper_fault = Event(mapper.status_topic.msg.status != ComponentStatus.STATUS_HEALTHY, handle_once=True)
activate_direct_sensor_mode = update_parameter(component=controller, param_name="use_direct_sensor", new_value=True)

# 3. RViz click -> Planner goal (the spec's event.OnGreater("rviz_goal", topic, 0, ["header", "stamp", "sec"]))
event_clicked_point = event.OnGreater(
    "rviz_goal",
    Topic(name="/clicked_point", msg_type="PointStamped"),
    0, ["header", "stamp", "sec"],
)
send_goal = ComponentActions.send_action_goal(
    action_name="/planner/plan_path",
    action_type=PlanPath,
    action_request_msg=PlanPath.Goal(),
)


def goal_point_parser(*, msg: PointStamped, **_):
    action_request = PlanPath.Goal()
    goal = Pose()
    goal.position.x = msg.point.x
    goal.position.y = msg.point.y
    action_request.goal = goal
    end_tolerance = PathTrackingError()
    end_tolerance.orientation_error = 0.2
    end_tolerance.lateral_distance_error = 0.05
    action_request.end_tolerance = end_tolerance
    return action_request


send_goal.event_parser(goal_point_parser, output_mapping="action_request_msg")

# --- Wire Events -> Actions ---
events_actions = {
    event_clicked_point: [LogInfo(msg="Got new goal point"), send_goal],
    event_controller_fail: unblock_action,
    event_mapper_fault: activate_direct_sensor_mode,
}

# --- The robot (Simulator) and the stand-ins (see the docstring) --------------------------------
odom_topic = Topic(name="/odometry/filtered", msg_type="Odometry")
clicked_point = Topic(name="/clicked_point", msg_type="PointStamped")  # the Operator stand-in clicks here
scan = Topic(name="/scan", msg_type="LaserScan")
mapper_scan = Topic(name="/mapper/scan", msg_type="LaserScan")
sim = Simulator("sim", config=SimulatorConfig(world="house", spawn=ROBOT_SPAWN, obstacles=[BLOCKING_WALL]))
sim.inputs(command=Topic(name="/cmd_vel", msg_type=cmd_msg_type))
sim.outputs(odom=odom_topic, scan=scan, map=Topic(name="/map", msg_type="OccupancyGrid"))
mapper.inputs(sensor_data=mapper_scan)
mapper.run_type = "Event"


class ScanDriver(BaseComponent):
    """The mapper's lidar driver: relays ``/scan``, then goes silent (a crash) after DROPOUT_AFTER s."""

    def custom_on_activate(self) -> None:
        self.started: float | None = None
        self.silent = False

    def _execution_step(self, msg: LaserScan = None, topic=None) -> None:
        now = time.monotonic()
        self.started = self.started or now
        if now - self.started < DROPOUT_AFTER:
            self.publish(mapper_scan, msg)
        elif not self.silent:
            self.silent = True
            self.get_logger().warning("[scan_driver] scan driver crashed: nothing more on %s", mapper_scan.name)
        self.health_status.set_healthy()


class Operator(BaseComponent):
    """Clicks GOAL once, when the robot's odometry is there and the Planner serves its action;
    then watches the robot (its position every 2 s)."""

    def custom_on_activate(self) -> None:
        self.clicked_at: float | None = None

    def _execution_step(self) -> None:
        self.health_status.set_healthy()
        odom = self.get_input(odom_topic)
        if odom is None or self.get_input(planner.status_topic) is None:
            return
        now = time.monotonic()
        if self.clicked_at is None:
            self.clicked_at = now
            self.publish(clicked_point, PointStamped(header=Header(stamp=Time.now(), frame_id="map"), point=Point(x=GOAL[0], y=GOAL[1])))
            self.get_logger().info("[rviz] clicked (%.2f, %.2f)", *GOAL)
        elif round((now - self.clicked_at) * 2) % 4 == 0:
            p = odom.pose.pose.position
            self.get_logger().info("[rviz] t=%4.1f s: robot at (%.2f, %.2f), %.2f m/s", now - self.clicked_at, p.x, p.y,
                                   odom.twist.twist.linear.x)


driver_stand_in = ScanDriver(component_name="scan_driver", inputs=[scan], outputs=[mapper_scan], trigger=scan)
operator = Operator(component_name="rviz", inputs=[odom_topic, planner.status_topic], outputs=[clicked_point],
                    config=BaseComponentConfig(loop_rate=2.0))

# --- Launch ---
launcher = Launcher()
launcher.add_pkg(components=[sim, driver_stand_in, operator], package_name="simulation", multiprocessing=True)
launcher.kompass(
    components=[planner, controller, mapper, driver],
    events_actions=events_actions,
    activate_all_components_on_start=True,
    multiprocessing=True,
)
launcher.inputs(location=odom_topic)
launcher.robot = my_robot
launcher.bringup()
