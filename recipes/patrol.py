"""Patrol the simulated house: visit four rooms, take a picture in each, come back; N laps.

    emos run recipes/patrol.py                      # one lap
    EMOS_PATROL_LAPS=20 EMOS_PATROL_WORLD=house_person emos run recipes/patrol.py  # docs/missions.md

The navigation stack (MapServer on the house map, Planner, Controller with Pure Pursuit on the
LocalMapper's grid, DriveManager) drives the Simulator's robot; a ``WaypointFollower`` (Nav2's
waypoint follower) sends it from room to room through the Planner's goal topic and saves the
Simulator's camera image at each room (``PhotoAtWaypoint``: the camera topic saved to a PNG;
the Vision component is not needed for a picture). A ``Behaviors`` component (Nav2's behavior
server) is the Controller's recovery ladder: clear the local grid, back up (checking behind),
spin. The ``Patrol`` component below sends the ``follow_waypoints`` goal, prints its feedback,
and writes ``summary.json`` (laps, missed waypoints with reasons, pictures, recoveries used,
collisions) to ``$EMOS_PATROL_OUT`` (default ``./patrol_out``). Exit code 0 when every lap was
done without a missed waypoint or a collision.
"""
import json
import os
import sys
import threading
import time

import numpy as np

from emos import Action, BaseComponent, Launcher, Topic
from emos.actors.nav import MapConfig, RobotConfig, RobotFrames, RobotGeometry, RobotType
from emos.actors.nav.components import (
    Controller,
    DriveManager,
    DriveManagerConfig,
    LocalMapper,
    LocalMapperConfig,
    MapServer,
    MapServerConfig,
    Planner,
    PlannerConfig,
    TopicsKeys,
)
from emos.actors.nav.components.behaviors import Behaviors, BehaviorsConfig
from emos.actors.nav.components.waypoints import WaypointFollower, WaypointFollowerConfig
from emos.actors.nav.controllers import ControllersID
from emos.actors.nav.missions import PhotoAtWaypoint
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.builders import HOUSE_DOCK, charging_dock

OUT_DIR = os.path.abspath(os.environ.get("EMOS_PATROL_OUT", "patrol_out"))
LAPS = int(os.environ.get("EMOS_PATROL_LAPS", "1"))
TIMEOUT = float(os.environ.get("EMOS_PATROL_TIMEOUT", str(600 * LAPS)))
HOUSE_MAP = os.path.join(os.path.dirname(__import__("emos.actors.sim.data", fromlist=["x"]).__file__), "house.yaml")
ROOMS = [(2.5, 2.0), (7.0, 2.5), (8.0, 5.5), (3.5, 5.5)]  # bottom-left, bottom-right, top-right, top-left
# Other waypoints (a JSON list of [x, y]) and Nav2's stop_on_failure (0/1) for tests and experiments.
ROOMS = [tuple(p) for p in json.loads(os.environ["EMOS_PATROL_ROOMS"])] if os.environ.get("EMOS_PATROL_ROOMS") else ROOMS
STOP_ON_FAILURE = os.environ.get("EMOS_PATROL_STOP_ON_FAILURE", "0") == "1"
HOME = (1.5, 1.5)
# "house_person": the same house with a person walking its rooms (the dynamic obstacle of the measure).
WORLD = os.environ.get("EMOS_PATROL_WORLD", "house")

my_robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                       geometry_params=np.array([0.2, 0.3]))
odom = Topic(name="/odom", msg_type="Odometry")  # the Simulator's true pose in the map frame (no localizer here)
scan = Topic(name="/scan", msg_type="LaserScan")
image = Topic(name="/camera/image", msg_type="Image")
control = Topic(name="/control", msg_type="Twist")

sim = Simulator("sim", config=SimulatorConfig(world=WORLD, obstacles=charging_dock(HOUSE_DOCK), camera_rate=2.0,
                                             camera_width=160, camera_height=120))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=odom, scan=scan, camera=image)

map_server = MapServer("global_map_server", config=MapServerConfig(map_file_path=HOUSE_MAP, grid_resolution=0.5))
planner = Planner("planner", config=PlannerConfig(loop_rate=1.0))
planner.run_type = "Timed"
controller = Controller("controller")
controller.algorithm = ControllersID.PURE_PURSUIT
controller.direct_sensor = False
driver = DriveManager("drive_manager", config=DriveManagerConfig(critical_zone_distance=0.05, critical_zone_angle=90.0,
                                                                 slowdown_zone_distance=0.3))
driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type="Twist"))
local_mapper = LocalMapper("mapper", config=LocalMapperConfig(map_params=MapConfig(width=3.0, height=3.0, resolution=0.05)))

behaviors = Behaviors("behaviors", config=BehaviorsConfig(local_mapper="mapper"))
behaviors.inputs(sensor_data=scan, location=odom, local_map=local_mapper.get_out_topic("local_map"))
behaviors.outputs(robot_command=control)  # through the DriveManager's safety zones
# Recovery ladder of the Controller (Nav2's recovery subtree): clear, back up, spin.
controller.on_algorithm_fail(action=[Action(method=behaviors.clear_costmaps), Action(method=behaviors.back_up),
                                     Action(method=behaviors.spin)], max_retries=3)

follower = WaypointFollower("waypoints", config=WaypointFollowerConfig(stop_on_failure=STOP_ON_FAILURE, waypoint_timeout=240.0),
                            tasks={i: PhotoAtWaypoint(image_topic=image.name, save_dir=os.path.join(OUT_DIR, "pictures"))
                                   for i in range(len(ROOMS))})
follower.inputs(location=odom, reached_end=planner.get_out_topic(TopicsKeys.REACHED_END),
                planner_status=Topic(name="planner/status", msg_type="ComponentStatus"), camera=image)
follower.outputs(goal_point=planner.get_in_topic(TopicsKeys.GOAL_POINT))


class Patrol(BaseComponent):
    """Sends the patrol to the WaypointFollower, prints its feedback, writes the summary."""

    def __init__(self) -> None:
        super().__init__(component_name="patrol", inputs=[odom], outputs=[])

    def custom_on_activate(self) -> None:
        threading.Thread(target=self._run, daemon=True, name="patrol").start()

    def _run(self) -> None:
        from emos.actors.nav.components.mission_interfaces import FollowWaypointsFeedback, FollowWaypointsGoal, FollowWaypointsResult
        from emos.core import control as C
        from emos.core.services import ActionClient
        from emos.msgs.geometry import Point, Pose

        while self.get_input(odom) is None:
            time.sleep(0.5)
        t0 = time.monotonic()
        last = [0.0]

        def feedback(fb: FollowWaypointsFeedback) -> None:
            if time.monotonic() - last[0] >= 5.0:
                last[0] = time.monotonic()
                print(f"[patrol] lap {fb.current_loop + 1}/{LAPS} waypoint {fb.current_waypoint} ({fb.state}): "
                      f"{fb.distance_remaining:.1f} m left", flush=True)

        poses = [Pose(position=Point(x=x, y=y)) for x, y in [*ROOMS, HOME]]
        client = ActionClient("waypoints/follow_waypoints", FollowWaypointsGoal, FollowWaypointsFeedback, FollowWaypointsResult,
                              ctx=self.node.ctx)
        try:
            result = client.send_goal(FollowWaypointsGoal(poses=poses, number_of_loops=LAPS - 1), feedback, timeout=TIMEOUT)
            summary = {"success": result.success, "message": result.message, "laps": result.loops_done,
                       "missed_waypoints": list(result.missed_waypoints)}
        except Exception as exc:  # noqa: BLE001 - the time limit or a lost server: reported
            summary = {"success": False, "message": f"{type(exc).__name__}: {exc}", "laps": None, "missed_waypoints": []}
        status = C.ControlClient("sim", self.node.ctx, timeout=10.0).execute_method("sim_status")
        summary["collisions"] = int(bool(status.get("collided", False)))
        summary["first_contacts"] = status.get("contacts", [])  # where it first touched something, if it did
        summary["recoveries"] = C.ControlClient("behaviors", self.node.ctx, timeout=10.0).execute_method("stats")
        pictures = os.path.join(OUT_DIR, "pictures")
        summary["pictures"] = sorted(os.listdir(pictures)) if os.path.isdir(pictures) else []
        summary["time_s"] = round(time.monotonic() - t0, 1)
        summary["success"] = bool(summary["success"]) and summary["collisions"] == 0
        os.makedirs(OUT_DIR, exist_ok=True)
        with open(os.path.join(OUT_DIR, "summary.json"), "w") as f:
            json.dump(summary, f)
        print("[patrol] " + json.dumps(summary), flush=True)
        C.call(os.environ["EMOS_SUPERVISOR_SOCKET"], C.SUPERVISOR_STOP, {"reason": "patrol finished"}, timeout=5.0)


launcher = Launcher()
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
launcher.kompass(components=[map_server, controller, planner, driver, local_mapper], multiprocessing=True)
launcher.add_pkg(components=[behaviors, follower, Patrol()], package_name="mission", multiprocessing=True)
for component in (controller, planner, driver, local_mapper):
    component.inputs(location=odom)
launcher.robot = my_robot
launcher.fallback_rate = 1 / 4  # one ladder step every 4 s: a back-up or a spin has time to finish
launcher.frames = RobotFrames(world="map", odom="map", scan="LDS-01")

summary_file = os.path.join(OUT_DIR, "summary.json")
if os.path.exists(summary_file):
    os.remove(summary_file)
launcher.bringup()
if not os.path.exists(summary_file):
    print("patrol: the mission did not finish (no summary)", file=sys.stderr)
    sys.exit(1)
with open(summary_file) as f:
    result = json.load(f)
print(f"patrol: {'SUCCESS' if result['success'] else 'FAILURE'} laps={result['laps']}/{LAPS} missed={result['missed_waypoints']} "
      f"pictures={len(result['pictures'])} recoveries={result['recoveries']} collisions={result['collisions']}", flush=True)
sys.exit(0 if result["success"] else 1)
