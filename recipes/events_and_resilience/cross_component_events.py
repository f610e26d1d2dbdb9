"""Cross-component healing (seed recipe): one component's status makes another one act.

    emos run recipes/events_and_resilience/cross_component_events.py --duration 6

A. The controller reports ALGORITHM_FAILURE (stuck in a corner): the drive manager runs its
   unblock manoeuvre (``keep_event_delay=60``: at most once a minute).
B. The local mapper stops being HEALTHY: the controller switches to direct sensor mode
   (``update_parameter``, ``handle_once=True``).
C. A point clicked on ``/clicked_point`` (``header.stamp.sec > 0``, the seed's ``OnGreater``):
   log it and send the planner a ``PlanPath`` goal built from the point by an event parser.

Stand-ins: ``Controller`` (gets stuck 1 s after start), ``LocalMapper`` (its sensor driver dies
at 2 s), ``DriveManager`` (logs its manoeuvre and publishes the command), ``Planner`` (an action
server ``/planner/plan_path``) and ``Clicker`` (an operator clicking once, at 3 s). ``PlanPath``
and ``PathTrackingError`` are declared here as the planner's interface.
"""
import time

from attrs import define, field

from emos import Action, BaseComponent, BaseComponentConfig, ComponentStatus, Event, Launcher, Topic
from emos.actions import ComponentActions, LogInfo, update_parameter
from emos.msgs import Point, PointStamped, Pose, Time, Twist, message_type
from emos.msgs import fields as F


@message_type("kompass_interfaces", name="PathTrackingError")
class PathTrackingError:
    orientation_error: float = F.float64()
    lateral_distance_error: float = F.float64()


@message_type("kompass_interfaces", name="PlanPath_Goal")
class PlanPathGoal:
    goal: Pose = F.message(Pose)
    end_tolerance: PathTrackingError = F.message(PathTrackingError)


@message_type("kompass_interfaces", name="PlanPath_Feedback")
class PlanPathFeedback:
    progress: float = F.float64()


@message_type("kompass_interfaces", name="PlanPath_Result")
class PlanPathResult:
    success: bool = F.boolean()


class PlanPath:
    """The planner's action interface, spelled as a ROS action type (``PlanPath.Goal()``)."""

    Goal, Feedback, Result = PlanPathGoal, PlanPathFeedback, PlanPathResult


clicked_point = Topic(name="/clicked_point", msg_type="PointStamped")
cmd_vel = Topic(name="/cmd_vel", msg_type="Twist")


@define(kw_only=True)
class ControllerConfig(BaseComponentConfig):
    use_direct_sensor: bool = field(default=False)


class Controller(BaseComponent):
    def custom_on_activate(self):
        self.t0, self.direct = time.monotonic(), self.config.use_direct_sensor

    def _execution_step(self):
        if self.config.use_direct_sensor != self.direct:
            self.direct = self.config.use_direct_sensor
            self.get_logger().info("[controller] direct sensor mode: %s", "on" if self.direct else "off")
        if 1.0 < time.monotonic() - self.t0 < 1.5:
            self.health_status.set_fail_algorithm(algorithm_names=["DWA"])
        else:
            self.health_status.set_healthy()


class LocalMapper(BaseComponent):
    def custom_on_activate(self):
        self.t0 = time.monotonic()

    def _execution_step(self):
        if time.monotonic() - self.t0 > 2.0:
            self.health_status.set_fail_component(component_names=["lidar_driver"])
        else:
            self.health_status.set_healthy()


class DriveManager(BaseComponent):
    def move_to_unblock(self):
        self.get_logger().info("[drive_manager] unblocking: rotating in place")
        self.publish(cmd_vel, Twist(angular={"x": 0.0, "y": 0.0, "z": 0.5}))
        return True


class Planner(BaseComponent):
    def custom_on_configure(self):
        self.create_action_server("/planner/plan_path", PlanPath.Goal, PlanPath.Feedback, PlanPath.Result, self.plan)

    def plan(self, goal_handle):
        g = goal_handle.goal
        self.get_logger().info("[planner] planning to (%.2f, %.2f) within %.2f m", g.goal.position.x, g.goal.position.y, g.end_tolerance.lateral_distance_error)
        return PlanPath.Result(success=True)


class Clicker(BaseComponent):
    """An operator clicking a goal in a map view, once, 3 s after start."""

    def custom_on_activate(self):
        self.t0, self.done = time.monotonic(), False

    def _execution_step(self):
        if not self.done and time.monotonic() - self.t0 > 3.0:
            msg = PointStamped(point=Point(x=2.0, y=0.5, z=0.0))
            msg.header.stamp = Time.now()
            self.publish(clicked_point, msg)
            self.done = True
        self.health_status.set_healthy()


planner = Planner(component_name="planner", config=BaseComponentConfig(loop_rate=1.0))
controller = Controller(component_name="controller", config=ControllerConfig(loop_rate=20.0))
mapper = LocalMapper(component_name="mapper", config=BaseComponentConfig(loop_rate=10.0))
driver = DriveManager(component_name="drive_manager", outputs=[cmd_vel])
clicker = Clicker(component_name="rviz", outputs=[clicked_point], config=BaseComponentConfig(loop_rate=10.0))

# 1. Controller stuck -> DriveManager unblocks
event_controller_fail = Event(controller.status_topic.msg.status == ComponentStatus.STATUS_FAILURE_ALGORITHM_LEVEL, keep_event_delay=60.0)
unblock_action = Action(method=driver.move_to_unblock)

# 2. Mapper down -> Controller switches to direct sensor mode
event_mapper_fault = Event(mapper.status_topic.msg.status != ComponentStatus.STATUS_HEALTHY, handle_once=True)
activate_direct_sensor_mode = update_parameter(component=controller, param_name="use_direct_sensor", new_value=True)

# 3. Clicked point -> Planner goal
event_clicked_point = Event(clicked_point.msg.header.stamp.sec > 0)
send_goal = ComponentActions.send_action_goal(action_name="/planner/plan_path", action_type=PlanPath, action_request_msg=PlanPath.Goal())


def goal_point_parser(*, msg: PointStamped, **_):
    action_request = PlanPath.Goal()
    goal = Pose()
    goal.position.x = msg.point.x
    goal.position.y = msg.point.y
    action_request.goal = goal
    action_request.end_tolerance = PathTrackingError(orientation_error=0.2, lateral_distance_error=0.05)
    return action_request


send_goal.event_parser(goal_point_parser, output_mapping="action_request_msg")

events_actions = {
    event_clicked_point: [LogInfo(msg="Got new goal point"), send_goal],
    event_controller_fail: unblock_action,
    event_mapper_fault: activate_direct_sensor_mode,
}

launcher = Launcher()
launcher.kompass(components=[planner, controller, mapper, driver, clicker], events_actions=events_actions,
                 activate_all_components_on_start=True, multiprocessing=True)
launcher.bringup()
