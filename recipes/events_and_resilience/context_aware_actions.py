"""Context-aware actions: the spec's semantic-navigation recipe, on the real navigation stack.

    emos run recipes/events_and_resilience/context_aware_actions.py --duration 60

A location name arriving on ``/user_command`` (while the ``LocalMapper`` is HEALTHY) calls
``navigate_to_location(command_topic.msg.data)``: the argument is read from the topic when the
event fires (dynamic injection), looked up in ``WAYPOINTS`` and published as a goal on
``/clicked_point`` with ``emos topic pub`` (the spec shells out to ``ros2 topic pub``); the
``Planner`` takes it as its ``goal_point`` and the Controller and DriveManager drive the robot
there.

What is real: Planner, Controller (DWA on the LocalMapper's grid), LocalMapper, DriveManager,
the Monitor running the event and the action, ``emos topic pub``, and the ``Simulator``
(pybullet, headless) standing in for the robot: the demo house, the robot in its first room,
its odometry, lidar and map.

Stood in: ``Operator`` is the person giving commands (a voice interface, a fleet manager): once
the robot is up (odometry, the mapper healthy) it says "garage" (not on the map: the lookup
refuses it) and then "kitchen"; it prints the robot's progress and when the Planner reports
arrival.

Differences from the spec's code: imports; ``WAYPOINTS``: "kitchen" is the spec's, the other two
are moved into the simulated house (the spec's "reception" is inside its wall, "station_a"
outside it); the goal goes out with ``emos topic pub`` to this run (``--run``, three copies 0.1 s
apart: a subscriber still connecting to the new publisher gets one; the spec's ``--once``);
``print`` flushes (the action runs in the Monitor's process, whose output is a log file);
``multiprocessing=True`` (errata); ``Twist`` commands (no ROS distro here); the Simulator
publishes the map the Planner needs.

The page's second half (a VLM prompt built from ``detections.msg.labels[0]``) is a snippet the
spec's complete recipe leaves out; its binding works the same way (tests check it).
"""
import os
import shlex
import subprocess
import sys
import time

import numpy as np

from emos import Action, BaseComponent, ComponentStatus, Event, Launcher, Topic
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.components import Controller, DriveManager, LocalMapper, Planner, PlannerConfig
from emos.actors.nav.controllers import ControllersID
from emos.actors.sim import Simulator, SimulatorConfig
from emos.config.base import BaseComponentConfig
from emos.msgs import String

ROBOT_SPAWN = (1.0, 2.0, 0.0)  # x, y, yaw in the house's first room, facing +x
COMMANDS = ("garage", "kitchen")  # what the operator says, 1 s apart

# --- Waypoint Database ---
WAYPOINTS = {
    "kitchen": {"x": 2.0, "y": 0.5},
    "reception": {"x": 1.0, "y": 2.0},  # the spec's (0.0, 0.0) is inside the house's wall
    "station_a": {"x": 7.0, "y": 2.5},  # the spec's (-1.5, 2.0) is outside the house
}


def navigate_to_location(location_name: str):
    key = location_name.strip().lower()
    if key not in WAYPOINTS:
        print(f"Unknown location: {key}", flush=True)
        return
    coords = WAYPOINTS[key]
    topic_cmd = (
        f"{shlex.quote(sys.executable)} -m emos topic pub --run {os.environ['EMOS_RUN_ID']} --rate 10 --count 3 "
        f"/clicked_point geometry_msgs/msg/PointStamped "
        f"'{{header: {{frame_id: \"map\"}}, point: {{x: {coords['x']}, y: {coords['y']}, z: 0.0}}}}'"
    )
    print(f"Going to {key} at ({coords['x']}, {coords['y']})", flush=True)
    subprocess.run(topic_cmd, shell=True, check=True, capture_output=True, timeout=8)


# --- Command Topic ---
command_topic = Topic(name="/user_command", msg_type="String")

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
goal_topic = Topic(name="/clicked_point", msg_type="PointStamped")
planner.inputs(goal_point=goal_topic)

controller = Controller(component_name="controller")
controller.direct_sensor = False
controller.algorithm = ControllersID.DWA

mapper = LocalMapper(component_name="mapper")
driver = DriveManager(component_name="drive_manager")
cmd_msg_type = "Twist"  # the spec picks TwistStamped for ROS 2 jazzy and later; no ROS distro here
driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type=cmd_msg_type))

# --- Context-Aware Event & Action ---
event_command_received = Event(
    event_condition=(command_topic & (mapper.status_topic.msg.status == ComponentStatus.STATUS_HEALTHY)),
)
action_process_command = Action(
    method=navigate_to_location,
    args=(command_topic.msg.data,),  # Dynamic injection
)

events_actions = {
    event_command_received: action_process_command,
}

# --- The robot (Simulator) and the operator (see the docstring) ---------------------------------
odom_topic = Topic(name="/odometry/filtered", msg_type="Odometry")
sim = Simulator("sim", config=SimulatorConfig(world="house", spawn=ROBOT_SPAWN))
sim.inputs(command=Topic(name="/cmd_vel", msg_type=cmd_msg_type))
sim.outputs(odom=odom_topic, map=Topic(name="/map", msg_type="OccupancyGrid"))


class Operator(BaseComponent):
    """Says COMMANDS once the robot is up; then prints its position every 2 s and its arrival."""

    def __init__(self) -> None:
        self.reached = planner.get_out_topic("reached_end")
        super().__init__(component_name="operator", inputs=[odom_topic, mapper.status_topic, self.reached],
                         outputs=[command_topic], config=BaseComponentConfig(loop_rate=2.0))

    def custom_on_activate(self) -> None:
        self.said: list[float] = []
        self.arrived = False
        self.printed = 0.0

    def _execution_step(self) -> None:
        self.health_status.set_healthy()
        odom, status = self.get_input(odom_topic), self.get_input(mapper.status_topic)
        if odom is None or status is None or (not self.said and status.status != ComponentStatus.STATUS_HEALTHY):
            return  # the robot is not up yet
        now = time.monotonic()
        if len(self.said) < len(COMMANDS) and (not self.said or now - self.said[-1] >= 1.0):
            word = COMMANDS[len(self.said)]
            self.get_logger().info("[operator] says %r on %s", word, command_topic.name)
            self.publish(command_topic, String(data=word))
            self.said.append(now)
            return
        reached = self.get_input(self.reached)
        p = odom.pose.pose.position
        if reached is not None and reached.data and not self.arrived:
            self.arrived = True
            self.get_logger().info("[operator] the planner reports arrival; robot at (%.2f, %.2f)", p.x, p.y)
        elif now - self.printed >= 2.0 and not self.arrived:
            self.printed = now
            self.get_logger().info("[operator] robot at (%.2f, %.2f), %.2f m/s", p.x, p.y, odom.twist.twist.linear.x)


# --- Launch ---
launcher = Launcher()
launcher.add_pkg(components=[sim, Operator()], package_name="simulation", multiprocessing=True)
launcher.kompass(
    components=[planner, controller, driver, mapper],
    activate_all_components_on_start=True,
    multiprocessing=True,
    events_actions=events_actions,
)
launcher.inputs(location=odom_topic)
launcher.robot = my_robot
launcher.bringup()
