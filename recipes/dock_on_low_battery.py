"""Low battery mid-mission: the robot leaves its patrol, docks, charges, undocks and resumes.

    emos run recipes/dock_on_low_battery.py

The house patrol of ``recipes/patrol.py`` (four rooms, one lap, no pictures here) with a charging
dock against the left wall of the top-left room (the Simulator's ``charging_dock``). A
``Battery`` stand-in publishes a ``BatteryState`` whose ``percentage`` falls while the robot is
off the dock and rises while it charges. An ``Event`` on ``percentage < 0.3`` runs
``Action(method=charger.go_charge)``: the ``ChargeManager`` cancels the waypoint mission
(``cancel_mission``), drives to the dock's staging pose through the Planner, pauses the
Controller (a lifecycle ``stop``: its plan ends at the staging pose, and it must not drive the
robot back there once the docking server lets go) and calls the
``DockingServer``'s ``dock_robot`` action, which finds the dock in the scan and docks. Charged
(``percentage`` >= 0.95) it calls ``undock_robot``, starts the Controller again and
``resume_mission``: the patrol goes on from the waypoint it left. ``summary.json`` in
``$EMOS_DOCK_OUT`` (default ``./dock_on_low_battery_out``) says what happened; exit code 0 when
the robot docked, charged and finished the patrol without a collision.
"""
import json
import math
import os
import sys
import threading
import time

import numpy as np

from emos import Action, BaseComponent, Event, Launcher, Topic
from emos.actors.nav import RobotConfig, RobotFrames, RobotGeometry, RobotType
from emos.actors.nav.components import TopicsKeys
from emos.actors.nav.components.docking import DockingServerConfig
from emos.actors.nav.components.waypoints import WaypointFollowerConfig
from emos.actors.nav.stacks import COMMAND_INPUTS, point_navigation_stack
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.builders import HOUSE_DOCK, charging_dock
from emos.msgs import BatteryState

OUT_DIR = os.path.abspath(os.environ.get("EMOS_DOCK_OUT", "dock_on_low_battery_out"))
TIMEOUT = float(os.environ.get("EMOS_DOCK_TIMEOUT", "900"))
HOUSE_MAP = os.path.join(os.path.dirname(__import__("emos.actors.sim.data", fromlist=["x"]).__file__), "house.yaml")
ROOMS = [(2.5, 2.0), (7.0, 2.5), (8.0, 5.5), (3.5, 5.5), (1.5, 1.5)]
DRAIN, CHARGE, LOW, FULL = 0.02, 0.1, 0.3, 0.95  # per s off / on the dock; the event's threshold; charged
DOCKED_OFFSET, STAGING_OFFSET = 0.42, 0.6  # the DriveManager's critical zone stays clear of the dock's arms when docked
STAGING = (HOUSE_DOCK[0] + (DOCKED_OFFSET + STAGING_OFFSET) * math.cos(HOUSE_DOCK[2]),
           HOUSE_DOCK[1] + (DOCKED_OFFSET + STAGING_OFFSET) * math.sin(HOUSE_DOCK[2]))

my_robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                       geometry_params=np.array([0.2, 0.3]))
odom = Topic(name="/odom", msg_type="Odometry")
scan = Topic(name="/scan", msg_type="LaserScan")
battery_topic = Topic(name="/battery_state", msg_type="BatteryState")

sim = Simulator("sim", config=SimulatorConfig(world="house", obstacles=charging_dock(HOUSE_DOCK)))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=odom, scan=scan)
# The house's point-navigation stack (recipes/patrol.py's); the DriveManager ranks the docking
# server's commands over the Controller's (COMMAND_INPUTS).
stack = point_navigation_stack(my_robot, RobotFrames(world="map", odom="map", scan="LDS-01"), HOUSE_MAP, odom=odom,
                               command=Topic(name="/cmd_vel", msg_type="Twist"), scan=scan, command_inputs=COMMAND_INPUTS)
planner = stack.planner
docking = stack.docking_server(config=DockingServerConfig(docks={"home": HOUSE_DOCK}, docked_offset=DOCKED_OFFSET,
                                                          staging_offset=STAGING_OFFSET, search_timeout=5.0))
follower = stack.waypoint_follower(config=WaypointFollowerConfig(stop_on_failure=False, waypoint_timeout=240.0))
goal_topic = planner.get_in_topic(TopicsKeys.GOAL_POINT)


class Battery(BaseComponent):
    """A battery stand-in: drains off the dock, charges on it (``set_charging``)."""

    def __init__(self) -> None:
        from emos.config.base import BaseComponentConfig

        super().__init__(component_name="battery", outputs=[battery_topic], config=BaseComponentConfig(loop_rate=2.0))

    def custom_on_activate(self) -> None:
        self.level, self.charging, self.last = 0.5, False, None

    def set_charging(self, on: bool) -> bool:
        self.charging = bool(on)
        return True

    def _execution_step(self) -> None:
        from emos.core import clock

        now = clock.now()
        if self.last is not None:
            rate = CHARGE if self.charging else -DRAIN
            self.level = float(np.clip(self.level + rate * (now - self.last), 0.0, 1.0))
        self.last = now
        self.publish(battery_topic, BatteryState(percentage=self.level, present=True))
        self.health_status.set_healthy()


class ChargeManager(BaseComponent):
    """Runs the patrol and, on the low-battery event, the trip to the dock and back."""

    def __init__(self) -> None:
        super().__init__(component_name="charger", inputs=[odom, battery_topic, planner.get_out_topic(TopicsKeys.REACHED_END)],
                         outputs=[goal_topic])

    def custom_on_activate(self) -> None:
        self.log: list = []
        self.busy = threading.Event()
        threading.Thread(target=self._patrol, daemon=True, name="patrol").start()

    # -- the event's action (runs in this process, returns at once) ------------------------------
    def go_charge(self) -> bool:
        if self.busy.is_set():
            return False
        self.busy.set()
        threading.Thread(target=self._charge, daemon=True, name="charge").start()
        return True

    def _say(self, what: str) -> None:
        self.log.append(what)
        print(f"[charger] {what}", flush=True)

    def _call(self, component: str, method: str, *args: object) -> object:
        from emos.core import control as C

        return C.ControlClient(component, self.node.ctx, timeout=30.0).execute_method(method, *args)

    def _lifecycle(self, component: str, op: str) -> None:
        from emos.core import control as C

        C.call(os.environ["EMOS_SUPERVISOR_SOCKET"], C.SUPERVISOR_LIFECYCLE,
               {"component": component, "request": op, "wait": True, "by": "component"}, timeout=30.0)

    def _pose(self) -> tuple:
        p = self.get_input(odom).pose.pose.position
        return (p.x, p.y)

    def _charge(self) -> None:
        from emos.actors.nav.components.mission_interfaces import DockRobotFeedback, DockRobotGoal, DockRobotResult, UndockRobotGoal
        from emos.core.services import ActionClient
        from emos.msgs import Header, Point, PointStamped

        level = self.get_input(battery_topic).percentage
        self._say(f"battery at {level:.0%}: leaving the patrol for the dock ({self._call('waypoints', 'cancel_mission')})")
        while math.dist(self._pose(), STAGING) > 0.2:  # the Planner takes the robot to the staging pose
            self.publish(goal_topic, PointStamped(header=Header(frame_id="map"), point=Point(x=STAGING[0], y=STAGING[1])))
            time.sleep(1.0)
        self._say("at the staging pose: the docking server drives now")
        self._lifecycle("controller", "stop")
        result = ActionClient("docking/dock_robot", DockRobotGoal, DockRobotFeedback, DockRobotResult, ctx=self.node.ctx).send_goal(
            DockRobotGoal(dock_id="home"), timeout=300)
        self._say(f"dock_robot: success={result.success} {result.message}")
        if result.success:
            self._call("battery", "set_charging", True)
            while self.get_input(battery_topic).percentage < FULL:
                time.sleep(0.5)
            self._call("battery", "set_charging", False)
            self._say(f"charged to {self.get_input(battery_topic).percentage:.0%}")
            result = ActionClient("docking/undock_robot", UndockRobotGoal, DockRobotFeedback, DockRobotResult,
                                  ctx=self.node.ctx).send_goal(UndockRobotGoal(), timeout=300)
            self._say(f"undock_robot: success={result.success} {result.message}")
        self._lifecycle("controller", "start")
        self._say(f"resume_mission: {self._call('waypoints', 'resume_mission')}")
        self.docked = result.success
        self.busy.clear()

    # -- the patrol ----------------------------------------------------------------------------------
    def _patrol(self) -> None:
        from emos.core import control as C

        while self.get_input(odom) is None:
            time.sleep(0.5)
        t0 = time.monotonic()
        self.docked = False
        self._say(f"patrol started: {self._call('waypoints', 'start_mission', ROOMS)}")
        status: dict = {}
        while time.monotonic() - t0 < TIMEOUT:
            time.sleep(1.0)
            status = self._call("waypoints", "mission_status")  # type: ignore[assignment]
            if not status["active"] and not status["paused"] and not self.busy.is_set() and status["result"] is not None:
                break
        sim_status = self._call("sim", "sim_status")
        result = status.get("result") or {}
        summary = {"patrol": result, "docked_and_charged": bool(self.docked), "log": self.log,
                   "collisions": int(bool(sim_status.get("collided", False))), "time_s": round(time.monotonic() - t0, 1)}
        summary["success"] = bool(result.get("success")) and summary["docked_and_charged"] and not summary["collisions"]
        os.makedirs(OUT_DIR, exist_ok=True)
        with open(os.path.join(OUT_DIR, "summary.json"), "w") as f:
            json.dump(summary, f)
        print("[charger] " + json.dumps(summary), flush=True)
        C.call(os.environ["EMOS_SUPERVISOR_SOCKET"], C.SUPERVISOR_STOP, {"reason": "mission finished"}, timeout=5.0)


charger = ChargeManager()
low_battery = Event(battery_topic.msg.percentage < LOW, handle_once=True)

launcher = Launcher()
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
stack.launch(launcher)
launcher.add_pkg(components=[docking, follower, Battery(), charger], package_name="mission", multiprocessing=True,
                 events_actions={low_battery: Action(method=charger.go_charge)})

summary_file = os.path.join(OUT_DIR, "summary.json")
if os.path.exists(summary_file):
    os.remove(summary_file)
launcher.bringup()
if not os.path.exists(summary_file):
    print("dock_on_low_battery: the mission did not finish (no summary)", file=sys.stderr)
    sys.exit(1)
with open(summary_file) as f:
    result = json.load(f)
print(f"dock_on_low_battery: {'SUCCESS' if result['success'] else 'FAILURE'} docked_and_charged={result['docked_and_charged']} "
      f"patrol={result['patrol']} collisions={result['collisions']}", flush=True)
sys.exit(0 if result["success"] else 1)
