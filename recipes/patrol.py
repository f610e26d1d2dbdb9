"""Patrol the simulated house: visit four rooms, take a picture in each, come back; N laps.

    emos run recipes/patrol.py                      # one lap
    EMOS_PATROL_LAPS=20 EMOS_PATROL_WORLD=house_person emos run recipes/patrol.py  # docs/missions.md
    EMOS_PATROL_LAPS=20 EMOS_PATROL_WORLD=house_person EMOS_PATROL_PEDESTRIAN=yielding emos run recipes/patrol.py

The point-navigation stack of ``emos.actors.nav.stacks`` (MapServer on the house map, Planner,
Controller with Pure Pursuit on the LocalMapper's grid, DriveManager) drives the Simulator's
robot; its DriveManager ranks the recovery behaviors' commands over the Controller's
(``COMMAND_INPUTS``, twist_mux's priorities). ``EMOS_PATROL_MOVERS=1`` gives the Controller the
moving-obstacle tracker instead (``movers=True``: the ArcSampler on CostToGo plans, its arcs
checked against where the tracked movers will be). A ``WaypointFollower`` (Nav2's
waypoint follower) sends it from room to room through the Planner's goal topic and saves the
Simulator's camera image at each room (``PhotoAtWaypoint``: the camera topic saved to a PNG;
the Vision component is not needed for a picture). A ``Behaviors`` component (Nav2's behavior
server) is the Controller's recovery ladder: clear the local grid, back up (checking behind),
spin; and it gives way to people (``GiveWayConfig``: on a collision course with a person the
scan tracker sees, it takes the robot over, above the Controller, and stands short, backs out of
the doorway or pulls aside until the way is clear; ``EMOS_PATROL_GIVE_WAY=0`` turns it off), while
the DriveManager's swept check counts where a tracked person will walk as an obstacle
(``mover_prediction_time``). The Behaviors' passage guard (``PassageGuardConfig``) remembers where
the person walked and holds the robot before that stretch of its path (the middle doorway and the
way to it) while the person would meet it there (``EMOS_PATROL_PASSAGE_GUARD=0`` turns it off), and
publishes that band to the Planner, whose ``CostToGo`` routes cross it instead of following it (the
people layer; ``EMOS_PATROL_PEOPLE_LAYER=0``: the stack's KPIECE1 planner). ``EMOS_PATROL_PEDESTRIAN=yielding`` makes the person stop for a
robot in its way (and turn back after a while) instead of walking through it. The ``Patrol`` component below sends the ``follow_waypoints`` goal, prints its feedback,
and writes ``summary.json`` (laps, missed waypoints with reasons, pictures, recoveries used,
collisions; every contact with a moving obstacle, classified by who closed the gap) to ``$EMOS_PATROL_OUT`` (default ``./patrol_out``). Exit code 0 when every lap was
done without a missed waypoint or a collision.
"""
import json
import os
import sys
import threading
import time

import attrs
import numpy as np

from emos import Action, BaseComponent, Launcher, Topic
from emos.actors.nav import RobotConfig, RobotFrames, RobotGeometry, RobotType
from emos.actors.nav.components.behaviors import BehaviorsConfig
from emos.actors.nav.components.keys import TopicsKeys
from emos.actors.nav.components.waypoints import WaypointFollowerConfig
from emos.actors.nav.missions import PhotoAtWaypoint
from emos.actors.nav.missions.passages import PassageGuardConfig
from emos.actors.nav.recovery import GiveWayConfig
from emos.actors.nav.stacks import COMMAND_INPUTS, point_navigation_stack
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.builders import HOUSE_DOCK, charging_dock
from emos.actors.sim.person import PERSON_RADIUS, house_person

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
# 1: the Controller tracks moving obstacles (stacks.point_navigation_stack(movers=True): the ArcSampler on CostToGo
# plans); 0 (the default): Pure Pursuit on the local grid. docs/missions.md compares the two with the walking person.
MOVERS = os.environ.get("EMOS_PATROL_MOVERS", "0") == "1"
# The walking person: "blind" (walks through whatever is in its way) or "yielding" (stops for the robot).
PEDESTRIAN = os.environ.get("EMOS_PATROL_PEDESTRIAN", "blind")
if PEDESTRIAN not in ("blind", "yielding"):
    sys.exit(f"patrol: EMOS_PATROL_PEDESTRIAN must be 'blind' or 'yielding', got {PEDESTRIAN!r}")
# 1 (the default): the Behaviors give way to the person, the DriveManager predicts its walk; 0: neither.
GIVE_WAY = os.environ.get("EMOS_PATROL_GIVE_WAY", "1") == "1"
# m/s of the give-way's moves (GiveWayConfig.speed): the person walks at 0.6 m/s, and backing slower is caught.
GIVE_WAY_SPEED = float(os.environ.get("EMOS_PATROL_GIVE_WAY_SPEED", "0.4"))
# 1 (the default): the Behaviors hold the robot before the stretch of its path where the person walks while the
# person would be there before the robot is through (PassageGuardConfig); 0: no passage guard.
PASSAGE_GUARD = os.environ.get("EMOS_PATROL_PASSAGE_GUARD", "1") == "1"
# 1 (the default): the Planner plans on CostToGo with the people layer (a soft cost where the guard's band says people
# walked: routes cross their way instead of following it; docs/missions.md, "Routes off the people's way"); 0: the
# stack's KPIECE1 planner, no layer.
PEOPLE_LAYER = os.environ.get("EMOS_PATROL_PEOPLE_LAYER", "1") == "1"
# The layer's weight (PeopleLayerConfig.weight; 10 here: the shortest crossing of the house person's walk, no contact
# in ten laps where 3 had one); 0: CostToGo's routes without the layer (for comparison).
PEOPLE_WEIGHT = float(os.environ.get("EMOS_PATROL_PEOPLE_WEIGHT", "10"))
# 1: a person out of view is predicted as people who left the view there came back (PassageGuardConfig.returns).
RETURNS = os.environ.get("EMOS_PATROL_RETURNS", "0") == "1"
# s a person out of view is still predicted from (PassageGuardConfig.out_of_view); past it the guard lets the robot in.
OUT_OF_VIEW = float(os.environ.get("EMOS_PATROL_OUT_OF_VIEW", "15"))
# s the robot waits at the band's edge for a person to come into view when none is known (PassageGuardConfig.unseen_wait;
# 20 s here: longer than the house person's 18.2 s walk there and back; docs/missions.md); 0: it goes in at once.
UNSEEN_WAIT = float(os.environ.get("EMOS_PATROL_UNSEEN_WAIT", "20"))
# s the people's walks are remembered (PassageGuardConfig.memory: the band where they walk, the walks predicted from;
# 600 held the robot longer, 434 s at most, and missed 3 waypoints in 6 laps: docs/missions.md).
MEMORY = float(os.environ.get("EMOS_PATROL_MEMORY", "180"))
MOVER_PREDICTION_TIME = 0.6  # s of a tracked person's walk the DriveManager's swept check treats as taken
# s without a status before the supervisor kills a component as hung (the Launcher's 2 s by default). On a machine
# at load 40-50 a 20-lap run is otherwise ended by restarts (the Simulator restarted puts the robot back at the spawn;
# more than 5 restarts in 10 s end the run): a measurement of the navigation, not of the supervisor, may raise it.
HEARTBEAT_TIMEOUT = float(os.environ.get("EMOS_PATROL_HEARTBEAT_TIMEOUT", "2.0"))

my_robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                       geometry_params=np.array([0.2, 0.3]))
odom = Topic(name="/odom", msg_type="Odometry")  # the Simulator's true pose in the map frame (no localizer here)
scan = Topic(name="/scan", msg_type="LaserScan")
image = Topic(name="/camera/image", msg_type="Image")

# The yielding person is the house_person world's person with the yielding model: the house plus that person.
people = [house_person(yielding=True)] if WORLD == "house_person" and PEDESTRIAN == "yielding" else []
sim = Simulator("sim", config=SimulatorConfig(world="house" if people else WORLD, obstacles=charging_dock(HOUSE_DOCK),
                                             moving_obstacles=people, camera_rate=2.0, camera_width=160, camera_height=120))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=odom, scan=scan, camera=image)

# The house's point-navigation stack; the DriveManager ranks the recovery behaviors over the Controller.
stack = point_navigation_stack(my_robot, RobotFrames(world="map", odom="map", scan="LDS-01"), HOUSE_MAP, odom=odom,
                               command=Topic(name="/cmd_vel", msg_type="Twist"), scan=scan, command_inputs=COMMAND_INPUTS,
                               movers=MOVERS, people_layer=PEOPLE_LAYER)
if PEOPLE_LAYER:
    stack.planner.config.people = attrs.evolve(stack.planner.config.people, weight=PEOPLE_WEIGHT)
behaviors = stack.behaviors(config=BehaviorsConfig(local_mapper=stack.local_mapper.component_name, max_rotational_vel=1.0,
                                                   give_way=GiveWayConfig(enabled=GIVE_WAY, speed=GIVE_WAY_SPEED),
                                                   passage_guard=PassageGuardConfig(enabled=PASSAGE_GUARD, out_of_view=OUT_OF_VIEW, memory=MEMORY,
                                                                                   unseen_wait=UNSEEN_WAIT, returns=RETURNS)))
behaviors.inputs(plan=stack.planner.get_out_topic(TopicsKeys.GLOBAL_PLAN))  # the passage guard looks along the plan
if GIVE_WAY:
    stack.driver.config.mover_prediction_time = MOVER_PREDICTION_TIME
# Recovery ladder of the Controller (Nav2's recovery subtree): clear, back up, spin.
stack.controller.on_algorithm_fail(action=[Action(method=behaviors.clear_costmaps), Action(method=behaviors.back_up),
                                           Action(method=behaviors.spin)], max_retries=3)
follower = stack.waypoint_follower(config=WaypointFollowerConfig(stop_on_failure=STOP_ON_FAILURE, waypoint_timeout=240.0),
                                   tasks={i: PhotoAtWaypoint(image_topic=image.name, save_dir=os.path.join(OUT_DIR, "pictures"))
                                          for i in range(len(ROOMS))})
follower.inputs(camera=image)


ROBOT_RADIUS = float(my_robot.geometry_params[0])


class ContactMonitor:
    """Watches the Simulator's ground truth (``sim_status``: the robot's pose, each mover's) and
    records every contact with a moving obstacle as an episode, classified by who closed the gap:
    ``robot_drove_into`` (the robot moved towards the person faster than 5 cm/s just before) or
    ``walked_into_robot`` (the robot was standing or moving away: the person, who walks on
    whatever is in the way, walked into it). The Simulator's own ``collided`` flag is sticky and
    counts one contact per run whatever happened after; these episodes count them all.
    Each episode's last ``TRACE_BEFORE`` s and next ``TRACE_AFTER`` s of the robot's and the
    movers' true positions go to ``contacts/contact_K.json`` and a picture on the map beside it."""

    TRACE_BEFORE, TRACE_AFTER = 20.0, 3.0  # s of ground truth kept around each contact

    def __init__(self, ctx: object, mover_radius: float = PERSON_RADIUS, period: float = 0.1) -> None:
        from collections import deque

        from emos.core import control as C

        self.client = C.ControlClient("sim", ctx, timeout=5.0)
        self.mover_radius, self.period = mover_radius, period
        self.episodes: list[dict] = []
        self.min_gap = float("inf")
        self._trace: deque = deque(maxlen=int((self.TRACE_BEFORE + self.TRACE_AFTER) / period) + 1)
        self._pending: list[int] = []  # episodes whose trace is not written yet
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="contact-monitor")
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        for k in self._pending:
            self._write_trace(k)

    def _write_trace(self, k: int) -> None:
        """The trace around episode ``k`` (see the class doc); a failure is reported, the run goes on."""
        episode, t0 = self.episodes[k], self.episodes[k]["sim_time"]
        rows = [r for r in self._trace if t0 - self.TRACE_BEFORE <= r["t"] <= t0 + self.TRACE_AFTER]
        out = os.path.join(OUT_DIR, "contacts", f"contact_{k}")
        try:
            os.makedirs(os.path.dirname(out), exist_ok=True)
            with open(out + ".json", "w") as f:
                json.dump({"episode": episode, "trace": rows}, f)
            from emos.actors.nav.maps import load_map
            from emos.tools.plotting import save_tracks_on_map

            tracks = {"robot": [[*r["robot"][:2], r["t"] - t0] for r in rows]}  # times from the contact
            for name in sorted({m for r in rows for m in r["movers"]}):
                tracks[name] = [[*r["movers"][name], r["t"] - t0] for r in rows if name in r["movers"]]
            save_tracks_on_map(out + ".png", load_map(HOUSE_MAP), f"contact {k} at {t0:.1f} s ({episode['kind']}): "
                               f"{self.TRACE_BEFORE:g} s before, {self.TRACE_AFTER:g} s after", tracks,
                               {"robot": episode["robot"][:2], episode["mover_name"]: episode["mover"][:2]})
        except Exception as exc:  # noqa: BLE001 - a picture must not stop the patrol: reported
            print(f"[patrol] contact {k}: trace not written to {out}.*: {type(exc).__name__}: {exc}", flush=True)

    def _run(self) -> None:
        prev, touching = None, False
        while not self._stop.wait(self.period):
            try:
                st = self.client.execute_method("sim_status")
            except Exception:  # noqa: BLE001 - the simulator may be busy or stopping: try again
                continue
            if "pose" not in st or not st.get("movers"):
                continue
            t, pose = float(st["sim_time"]), np.array(st["pose"][:2])
            self._trace.append({"t": round(t, 2), "robot": [round(float(x), 3) for x in st["pose"]],
                                "movers": {m["name"]: [round(float(x), 3) for x in m["pose"][:2]] for m in st["movers"]}})
            while self._pending and t >= self.episodes[self._pending[0]]["sim_time"] + self.TRACE_AFTER:
                self._write_trace(self._pending.pop(0))
            was_touching, touching = touching, False
            for mover in st["movers"]:
                mp = np.array(mover["pose"][:2])
                gap = float(np.linalg.norm(mp - pose)) - ROBOT_RADIUS - self.mover_radius
                self.min_gap = min(self.min_gap, gap)
                touching = touching or gap <= 0.005
                if gap <= 0.005 and not was_touching:
                    toward = mp - pose
                    toward /= max(float(np.linalg.norm(toward)), 1e-9)
                    v = (pose - prev[1]) / max(t - prev[0], 1e-3) if prev is not None else np.zeros(2)
                    closing = float(v @ toward)
                    self.episodes.append({"sim_time": round(t, 2), "robot": [round(float(x), 2) for x in st["pose"]],
                                          "mover": [round(float(x), 2) for x in mover["pose"]], "mover_name": mover["name"],
                                          "robot_speed_toward": round(closing, 3), "robot_speed": round(float(np.linalg.norm(v)), 3),
                                          "kind": "robot_drove_into" if closing > 0.05 else "walked_into_robot"})
                    print(f"[patrol] contact with {mover['name']}: {json.dumps(self.episodes[-1])}", flush=True)
                    self._pending.append(len(self.episodes) - 1)
            prev = (t, pose)


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
        monitor = ContactMonitor(self.node.ctx)
        client = ActionClient("waypoints/follow_waypoints", FollowWaypointsGoal, FollowWaypointsFeedback, FollowWaypointsResult,
                              ctx=self.node.ctx)
        try:
            result = client.send_goal(FollowWaypointsGoal(poses=poses, number_of_loops=LAPS - 1), feedback, timeout=TIMEOUT)
            summary = {"success": result.success, "message": result.message, "laps": result.loops_done,
                       "missed_waypoints": list(result.missed_waypoints)}
        except Exception as exc:  # noqa: BLE001 - the time limit or a lost server: reported
            summary = {"success": False, "message": f"{type(exc).__name__}: {exc}", "laps": None, "missed_waypoints": []}
        monitor.stop()
        summary["mover_contacts"] = monitor.episodes
        summary["mover_contacts_by_kind"] = {kind: sum(e["kind"] == kind for e in monitor.episodes)
                                             for kind in ("robot_drove_into", "walked_into_robot")}
        summary["mover_min_gap_m"] = round(monitor.min_gap, 3)
        status = C.ControlClient("sim", self.node.ctx, timeout=10.0).execute_method("sim_status")
        # The Simulator's flag is sticky (one per run); the monitor counts every contact with a mover.
        summary["sim_collided"] = bool(status.get("collided", False))
        summary["collisions"] = max(len(monitor.episodes), int(summary["sim_collided"]))
        summary["first_contacts"] = status.get("contacts", [])  # where it first touched something, if it did
        summary["recoveries"] = C.ControlClient("behaviors", self.node.ctx, timeout=10.0).execute_method("stats")
        summary["setup"] = {"pedestrian": PEDESTRIAN, "give_way": GIVE_WAY, "passage_guard": PASSAGE_GUARD, "movers_controller": MOVERS,
                            "people_layer_weight": PEOPLE_WEIGHT if PEOPLE_LAYER else None,
                            "planner": stack.planner.config.planner_id, "returns": RETURNS, "unseen_wait_s": UNSEEN_WAIT}
        pictures = os.path.join(OUT_DIR, "pictures")
        summary["pictures"] = sorted(os.listdir(pictures)) if os.path.isdir(pictures) else []
        summary["time_s"] = round(time.monotonic() - t0, 1)
        summary["success"] = bool(summary["success"]) and summary["collisions"] == 0
        os.makedirs(OUT_DIR, exist_ok=True)
        with open(os.path.join(OUT_DIR, "summary.json"), "w") as f:
            json.dump(summary, f)
        print("[patrol] " + json.dumps(summary), flush=True)
        C.call(os.environ["EMOS_SUPERVISOR_SOCKET"], C.SUPERVISOR_STOP, {"reason": "patrol finished"}, timeout=5.0)


launcher = Launcher(heartbeat_timeout=HEARTBEAT_TIMEOUT)
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
stack.launch(launcher)
launcher.add_pkg(components=[behaviors, follower, Patrol()], package_name="mission", multiprocessing=True)
# One ladder step every 4 s: a back-up or a spin has time to finish. On the Controller's own config:
# a component with its own handlers (on_algorithm_fail above) keeps its fallback_rate (100 Hz by
# default), whatever launcher.fallback_rate says (that one paces the launcher-wide policies).
stack.controller.config.fallback_rate = 1 / 4

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
