"""Logic gates and composed events (seed recipe): & | ~ over several topics.

    emos run recipes/events_and_resilience/composed_events.py --duration 25

The spec's four composed events, on a robot docking at a wall of the simulated house:

* smart stop: obstacle closer than 0.3 m AND moving faster than 0.1 m/s (``on_change``), whose
  action is the real ``DriveManager``'s ``stop`` (it holds the robot still for
  ``stop_hold_time`` s whatever commands arrive);
* conditional cognition: a person detected AND battery above 20 % (``keep_event_delay=5``);
* redundant sensors: front lidar closer than 0.2 m OR bumper pressed;
* exclusion: a person seen AND NOT in manual override.

The story: an operator drives the robot by hand (manual override on, battery at 15 %) fast
toward its dock at the west wall. The smart stop fires once, as the robot closes in fast, and
the DriveManager holds it; the operator then creeps in at 0.05 m/s, close to the wall but slow,
and the smart stop rightly stays quiet. At the dock the front lidar and the bumper report the
contact (the OR event, once); docked, the operator hands over (manual override off) and the
robot charges (battery 50 %): the person in view is now worth describing (AND) and tracking
(AND NOT), each once.

Real: the ``Simulator`` (pybullet, headless, the demo house) with its odometry on ``/odom`` and
its lidar on ``/scan``; the ``DriveManager`` between the operator's commands and the simulated
base (``/control`` -> ``/cmd_vel``), with its own safety zones on the scan; the Monitor that
evaluates the events in publish order across topics. Radar and odometry keep the spec's
``data_timeout``s: stale data never fires the smart stop.

Stood in (the simulator has no such sensors, and they are not the point): ``Peripherals`` makes
the front radar (``/radar_front``: nearest lidar return within +-15 deg ahead, beyond the
footprint) and the front range sensor (``/scan_front``, +-30 deg) from the simulated scan, and
publishes the bumper (pressed within 0.15 m of the wall), the battery, the manual override and
a person's detections (the event-driven cognition recipe runs the real detector on the
simulated camera); ``Operator`` is the hand on the joystick. Each event other than the smart
stop has no action on the spec's page, so its action logs a line naming it.
"""
import logging
import math

import numpy as np

from emos import Action, BaseComponent, BaseComponentConfig, Event, Launcher, Topic
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.components import DriveManager
from emos.actors.sim import Simulator, SimulatorConfig
from emos.msgs import Bool, Detections, Float32, Twist

ROBOT_RADIUS = 0.1  # m, the cylinder of the spec's TurtleBot-sized robot (radius, height 0.3)
SPAWN = (1.3, 2.0, math.pi)  # x, y, yaw: in the house's first room, facing the west wall (x = 0)
FAST, SLOW = 0.4, 0.05  # m/s: the approach, and the creep into the dock

# --- The spec's topics and events ---------------------------------------------------------------
# Radar distance reading (0.2s timeout for safety-critical data)
radar = Topic(name="/radar_front", msg_type="Float32", data_timeout=0.2)
# Odometry (0.5s timeout)
odom = Topic(name="/odom", msg_type="Odometry", data_timeout=0.5)

# Navigation: smart emergency stop
is_obstacle_close = radar.msg.data < 0.3
is_robot_moving_fast = odom.msg.twist.twist.linear.x > 0.1
event_smart_stop = Event(event_condition=(is_obstacle_close & is_robot_moving_fast), on_change=True)

driver = DriveManager(component_name="drive_manager")
stop_action = Action(method=driver.stop)

# Intelligence: conditional cognition
detections = Topic(name="/detections", msg_type="Detections")
battery = Topic(name="/battery_state", msg_type="Float32")
person_detected = detections.msg.labels.contains_any(["person"])
battery_ok = battery.msg.data > 20.0
event_describe_person = Event(event_condition=(person_detected & battery_ok), on_change=True, keep_event_delay=5)

# OR: redundant sensors
lidar = Topic(name="/scan_front", msg_type="Float32")
bumper = Topic(name="/bumper", msg_type="Bool")
is_lidar_blocked = lidar.msg.data < 0.2
is_bumper_pressed = bumper.msg.data == True  # noqa: E712 (a condition, not a comparison)
event_any_collision = Event(event_condition=(is_lidar_blocked | is_bumper_pressed), on_change=True)

# NOT: exclusion
manual_mode = Topic(name="/manual_override", msg_type="Bool")
target_seen = detections.msg.labels.contains_any(["person"])
event_auto_track = Event(event_condition=(target_seen & ~manual_mode.msg.data), on_change=True)


def announce(what: str):
    logging.getLogger("recipe").info("EVENT %s", what)


events_actions = {
    event_smart_stop: stop_action,
    event_describe_person: Action(announce, args=("describe person (battery ok)",)),
    event_any_collision: Action(announce, args=("collision (lidar or bumper)",)),
    event_auto_track: Action(announce, args=("auto-track person (not in manual mode)",)),
}

# --- The robot: the simulated house, and the DriveManager between the operator and the base -----
my_robot = RobotConfig(
    model_type=RobotType.DIFFERENTIAL_DRIVE,
    geometry_type=RobotGeometry.Type.CYLINDER,
    geometry_params=np.array([ROBOT_RADIUS, 0.3]),
    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.5, max_acc=1.5, max_decel=2.5),
    ctrl_omega_limits=AngularCtrlLimits(max_vel=0.4, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
)
sim = Simulator("sim", config=SimulatorConfig(world="house", spawn=SPAWN))
scan = sim.get_out_topic("scan")
control = driver.get_in_topic("command")  # /control: what the operator asks for
cmd_vel = driver.get_out_topic("robot_command")  # /cmd_vel: what the DriveManager lets through


# --- Stand-ins (see the module doc) -----------------------------------------------------------
def nearest_ahead(msg, half_angle_deg: float) -> float:
    """Nearest return within +-half_angle of straight ahead, beyond the footprint (m)."""
    ranges = np.asarray(msg.ranges, dtype=float)
    angles = msg.angle_min + msg.angle_increment * np.arange(ranges.size)
    ahead = np.abs(np.remainder(angles + math.pi, 2 * math.pi) - math.pi) <= math.radians(half_angle_deg)
    # Returns inside the footprint are the robot's own body (the simulated lidar sits in it).
    hits = ranges[ahead & np.isfinite(ranges) & (ranges > ROBOT_RADIUS)]
    return float(hits.min()) - ROBOT_RADIUS if hits.size else math.inf


class Peripherals(BaseComponent):
    """Radar and front range from the simulated scan; bumper, battery, override, detections."""

    def custom_on_activate(self):
        self.docked = False

    def _execution_step(self, msg=None, topic=None):
        front = nearest_ahead(msg, 15.0)
        self.docked = self.docked or front < 0.15  # the bumper touches the dock, and stays docked
        self.publish(radar, Float32(data=front))
        self.publish(lidar, Float32(data=nearest_ahead(msg, 30.0)))
        self.publish(bumper, Bool(data=self.docked))
        self.publish(battery, Float32(data=50.0 if self.docked else 15.0))  # charging once docked
        self.publish(manual_mode, Bool(data=not self.docked))  # the operator hands over at the dock
        self.publish(detections, Detections(labels=["person"], scores=np.ones(1), boxes=np.array([[100.0, 40.0, 160.0, 220.0]])))
        self.health_status.set_healthy()


def twist(speed: float) -> Twist:
    msg = Twist()
    msg.linear.x = speed
    return msg


class Operator(BaseComponent):
    """Drives fast at the dock; once the robot is stopped on the way, creeps in slowly."""

    def custom_on_activate(self):
        self.phase, self.driven = "approach", False

    def _execution_step(self):
        out = self.get_input(cmd_vel)
        let_through = out.linear.x if out is not None else 0.0
        if self.phase == "approach":
            if let_through > 0.05:
                self.driven = True
                self.last_seen = (self.get_input(radar), self.get_input(odom))
            elif self.driven and let_through == 0.0:
                self.phase = "creep"
                near, moving = self.last_seen
                print(f"[operator] the robot was stopped on the way (last seen at radar {near.data if near else float('nan'):.2f} m, "
                      f"{moving.twist.twist.linear.x if moving else float('nan'):.2f} m/s): creeping into the dock", flush=True)
        docked = self.get_input(bumper)
        if self.phase == "creep" and docked is not None and docked.data:
            self.phase = "docked"
            print("[operator] docked: handing over", flush=True)
        speed = {"approach": FAST, "creep": SLOW, "docked": 0.0}[self.phase]
        self.publish(control, twist(speed))
        self.health_status.set_healthy()


peripherals = Peripherals(component_name="peripherals", inputs=[scan],
                          outputs=[radar, lidar, bumper, battery, manual_mode, detections], trigger=scan)
operator = Operator(component_name="operator", inputs=[cmd_vel, bumper, radar, odom], outputs=[control],
                    config=BaseComponentConfig(loop_rate=10.0))

launcher = Launcher()
launcher.add_pkg(components=[driver], events_actions=events_actions, multiprocessing=True)
launcher.add_pkg(components=[sim, peripherals, operator], multiprocessing=True, package_name="simulation")
launcher.robot = my_robot
launcher.bringup()
