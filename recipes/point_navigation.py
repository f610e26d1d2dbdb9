"""Point navigation in the spec's TurtleBot3 arena: the spec's point-navigation recipe, ported.

    emos run recipes/point_navigation.py          # or: python recipes/point_navigation.py
    EMOS_UI=1 emos run recipes/point_navigation.py   # and watch it in the web UI

The navigation stack of the spec (MapServer, Planner, Controller with Pure Pursuit on the
LocalMapper's grid, DriveManager with safety zones) drives the robot in the spec's map, the
TurtleBot3 Webots arena (``turtlebot3_webots.yaml`` in the ``kompass_sim`` share directory),
which the ``Simulator`` (pybullet, headless) builds from the same file in place of Webots: to a
first goal round the table in front of the robot, then to a second one past the armchair at the
other end of the room.

Goals and progress come from a small ``Mission`` component defined here, so that the run needs
nobody at the web UI and judges itself: it publishes each goal on the planner's ``goal_point``
topic, prints progress once a second (distance left, speed, every component's health), and when
the robot arrives (``reached_end``) sends the next goal. At the end it writes ``summary.json`` and the
recipe draws ``point_navigation.png`` (map, plans, driven path). Exit code 0 only when both
goals were reached without a collision; 1 otherwise (a time limit of ``MISSION_TIMEOUT`` s).
Outputs go to ``$EMOS_NAV_OUT`` (default ``./point_navigation_out``).

The Mission may itself be killed and restarted (the chaos suite does): it keeps its progress
(current goal, results, driven path, start time) in ``mission.json`` in the run directory and a
restarted Mission resumes from there instead of sending the robot back to the first goal. It
repeats the current goal every 2 s, so a restarted Planner (which starts without one) gets it.
Under ``emos chaos run`` (``EMOS_CHAOS_RESULT`` set) it also writes
``{"goals", "goals_reached", "collisions", "late_s"}`` to that file for the chaos runner;
``late_s`` is the mission time beyond ``EMOS_NAV_NOMINAL_S`` (the fault-free time), null if unset.
"""
import json
import math
import os
import sys
import time

import numpy as np

from emos import BaseComponent, Launcher, Topic
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, MapConfig, RobotConfig, RobotFrames, RobotGeometry, RobotType
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
from emos.actors.nav.controllers import ControllersID
from emos.actors.sim import Simulator, SimulatorConfig
from emos.config.base import BaseComponentConfig
from emos.msgs import Header, Point, PointStamped
from emos.packages import get_package_share_directory

kompass_sim_dir = get_package_share_directory(package_name="kompass_sim")
map_file = os.path.join(kompass_sim_dir, "maps", "turtlebot3_webots.yaml")

OUT_DIR = os.path.abspath(os.environ.get("EMOS_NAV_OUT", "point_navigation_out"))
GOALS = [(1.5, -3.2), (-0.2, 2.4)]  # round the table, then up the room past the armchair
MISSION_TIMEOUT = float(os.environ.get("EMOS_NAV_TIMEOUT", "240"))
NAV_COMPONENTS = ["global_map_server", "planner", "controller", "drive_manager", "mapper"]

# 1. Robot configuration (the spec's TurtleBot-sized robot)
my_robot = RobotConfig(
    model_type=RobotType.DIFFERENTIAL_DRIVE,
    geometry_type=RobotGeometry.Type.CYLINDER,
    geometry_params=np.array([0.1, 0.3]),
    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.4, max_acc=1.5, max_decel=2.5),
    ctrl_omega_limits=AngularCtrlLimits(max_vel=0.4, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
)

# 2. Components
planner = Planner(component_name="planner", config=PlannerConfig(loop_rate=1.0))
planner.run_type = "Timed"

controller = Controller(component_name="controller")
controller.algorithm = ControllersID.PURE_PURSUIT
controller.direct_sensor = False  # obstacles from the LocalMapper's grid

driver = DriveManager(
    component_name="drive_manager",
    config=DriveManagerConfig(critical_zone_distance=0.05, critical_zone_angle=90.0, slowdown_zone_distance=0.3),
)
driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type="Twist"))  # no ROS distributions here: Twist

# 3. Mapping: a 3 x 3 m local grid, and the spec's map of the Webots arena
local_mapper = LocalMapper(
    component_name="mapper",
    config=LocalMapperConfig(map_params=MapConfig(width=3.0, height=3.0, resolution=0.05)),
)
map_server = MapServer(
    component_name="global_map_server",
    config=MapServerConfig(map_file_path=map_file, grid_resolution=0.5),
)

# 4. The simulated robot and arena, built from the same map (instead of Webots); the robot
# starts where the map's frame starts, as in Webots
odom_topic = Topic(name="/odometry/filtered", msg_type="Odometry")
sim = Simulator("sim", config=SimulatorConfig(world=map_file, spawn=(0.0, 0.0, 0.0)))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=odom_topic)


class Mission(BaseComponent):
    """Sends the goals one after the other, prints progress, and ends the run with a summary."""

    def __init__(self) -> None:
        self.odom, self.reached = odom_topic, planner.get_out_topic(TopicsKeys.REACHED_END)
        self.plan = planner.get_out_topic(TopicsKeys.GLOBAL_PLAN)
        self.goal = planner.get_in_topic(TopicsKeys.GOAL_POINT)
        self.statuses = [Topic(name=f"{name}/status", msg_type="ComponentStatus") for name in NAV_COMPONENTS]
        super().__init__(component_name="mission", inputs=[self.odom, self.reached, self.plan, *self.statuses],
                         outputs=[self.goal], config=BaseComponentConfig(loop_rate=5.0))

    def custom_on_activate(self) -> None:
        from emos.actors.nav.maps import distance_map, load_map

        self.clearance_map = load_map(map_file)
        self.distance = distance_map(self.clearance_map)
        self.t0 = time.monotonic()
        self.index = -1
        self.driven: list = []
        self.plans: list = []
        self.results: list = []
        self.min_clearance = math.inf
        self.last_print = 0.0
        self.done = False
        self.state_file = self.node.ctx.run_dir / "mission.json"
        self.resumed = False
        self._resume()

    # -- progress survives a restart of this component (CLOCK_MONOTONIC is shared by processes) --
    def _resume(self) -> None:
        try:
            state = json.loads(self.state_file.read_text())
        except FileNotFoundError:
            return
        except (OSError, ValueError) as exc:
            print(f"[mission] cannot read {self.state_file} ({exc}): starting from the first goal", flush=True)
            return
        self.t0, self.index, self.goal_sent_at = state["t0"], state["index"], state["goal_sent_at"]
        self.results, self.driven, self.plans = state["results"], [tuple(p) for p in state["driven"]], state["plans"]
        self.min_clearance = state["min_clearance"] if state["min_clearance"] is not None else math.inf
        self.resumed = True
        print(f"[mission] restarted: resuming at goal {self.index + 1}/{len(GOALS)}", flush=True)
        if 0 <= self.index < len(GOALS):  # the planner may have lost the goal too (it may have been killed with us)
            x, y = GOALS[self.index]
            self.publish(self.goal, PointStamped(header=Header(frame_id="map"), point=Point(x=x, y=y)))

    def _save(self) -> None:
        state = {"t0": self.t0, "index": self.index, "goal_sent_at": getattr(self, "goal_sent_at", self.t0),
                 "results": self.results, "driven": self.driven, "plans": self.plans,
                 "min_clearance": None if math.isinf(self.min_clearance) else self.min_clearance}
        tmp = self.state_file.with_suffix(".tmp")
        tmp.write_text(json.dumps(state))
        os.replace(tmp, self.state_file)

    def _send_next(self) -> None:
        self.resumed = False
        self.index += 1
        x, y = GOALS[self.index]
        self.goal_sent_at = time.monotonic()
        self.publish(self.goal, PointStamped(header=Header(frame_id="map"), point=Point(x=x, y=y)))
        self._save()
        print(f"[mission] goal {self.index + 1}/{len(GOALS)}: ({x:.2f}, {y:.2f})", flush=True)

    def _execution_step(self) -> None:
        if self.done:
            return
        odom = self.get_input(self.odom)
        if odom is None:
            return  # the simulator is starting
        if self.index < 0:
            self._send_next()
        p = odom.pose.pose.position
        pose = (p.x, p.y)
        if not self.driven or math.dist(self.driven[-1], pose) > 0.01:
            self.driven.append(pose)
        cell = self.clearance_map.world_to_grid(np.array(pose))
        if self.clearance_map.in_bounds(cell):
            self.min_clearance = min(self.min_clearance, float(self.distance[cell[1], cell[0]]) - my_robot.radius)
        now = time.monotonic()
        goal = GOALS[self.index]
        plan = self.get_input(self.plan)
        if plan is not None and len(plan.poses) and (not self.plans or self.plans[-1][0] != self.index):
            end = plan.poses[-1].pose.position
            if math.dist((end.x, end.y), goal) < 0.2:  # the first plan to this goal
                self.plans.append((self.index, [(q.pose.position.x, q.pose.position.y) for q in plan.poses]))
        left = math.dist(pose, goal)
        if now - self.goal_sent_at >= 2.0 and now - getattr(self, "goal_repeated_at", 0.0) >= 2.0:
            # A restarted Planner starts without a goal (a topic keeps no message for late
            # subscribers): repeat the current one; the Planner ignores a goal it already has.
            self.goal_repeated_at = now
            self.publish(self.goal, PointStamped(header=Header(frame_id="map"), point=Point(x=goal[0], y=goal[1])))
        if now - self.last_print >= 1.0:
            self.last_print = now
            self._save()
            speed = odom.twist.twist.linear.x
            health = " ".join(f"{t.name.split('/')[1]}={self._health(t)}" for t in self.statuses)
            print(f"[mission] t={now - self.t0:5.1f}s goal {self.index + 1}: {left:5.2f} m left, "
                  f"{speed:4.2f} m/s | {health}", flush=True)
        reached = self.get_input(self.reached)
        said_reached = reached is not None and reached.data and left <= 0.3 and self.input_age(self.reached) < now - self.goal_sent_at + 1e-3
        # The planner says "reached" once; a Mission restarted since the goal was sent may have
        # missed it, so it judges arrival as the planner does (within its distance_tolerance).
        if said_reached or (self.resumed and left <= planner.config.distance_tolerance):
            self.resumed = False
            self.results.append({"goal": goal, "reached": True, "time_s": round(now - self.goal_sent_at, 1)})
            print(f"[mission] goal {self.index + 1} reached in {now - self.goal_sent_at:.1f} s", flush=True)
            if self.index + 1 < len(GOALS):
                self._send_next()
            else:
                self._finish()
        elif now - self.t0 > MISSION_TIMEOUT:
            self.results.append({"goal": goal, "reached": False, "time_s": round(now - self.goal_sent_at, 1)})
            print(f"[mission] time limit of {MISSION_TIMEOUT:.0f} s: goal {self.index + 1} not reached", flush=True)
            self._finish()
        self.health_status.set_healthy()

    def _health(self, topic: Topic) -> str:
        msg = self.get_input(topic)
        return "?" if msg is None else ("ok", "ALGO", "COMP", "SYS", "gen")[min(int(msg.status), 4)]

    def _finish(self) -> None:
        from emos.core import control

        self.done = True
        status = control.ControlClient("sim", self.node.ctx, timeout=5.0).execute_method("sim_status")
        length = float(sum(math.dist(a, b) for a, b in zip(self.driven, self.driven[1:])))
        summary = {
            "reached": [r["reached"] for r in self.results] + [False] * (len(GOALS) - len(self.results)),
            "goals": self.results, "time_s": round(time.monotonic() - self.t0, 1), "path_length_m": round(length, 2),
            "min_clearance_m": round(self.min_clearance, 3), "collided": bool(status.get("collided", False)),
        }
        summary["success"] = all(summary["reached"]) and not summary["collided"]
        os.makedirs(OUT_DIR, exist_ok=True)
        with open(os.path.join(OUT_DIR, "summary.json"), "w") as f:
            json.dump(dict(summary, driven=self.driven, plans=self.plans), f)
        if os.environ.get("EMOS_CHAOS_RESULT"):  # the chaos runner's workload result
            nominal = os.environ.get("EMOS_NAV_NOMINAL_S")
            with open(os.environ["EMOS_CHAOS_RESULT"], "w") as f:
                json.dump({"goals": len(GOALS), "goals_reached": sum(summary["reached"]), "collisions": int(summary["collided"]),
                           "late_s": None if not nominal else round(summary["time_s"] - float(nominal), 1)}, f)
        print("[mission] " + json.dumps(summary), flush=True)
        # End the whole run through the supervisor's socket.
        control.call(os.environ["EMOS_SUPERVISOR_SOCKET"], control.SUPERVISOR_STOP, {"reason": "mission finished"}, timeout=5.0)


def draw(summary: dict, png: str) -> None:
    """Top-down picture: the map, each plan, and the driven path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from emos.actors.nav.maps import load_map

    grid = load_map(map_file)
    xmin, ymin, xmax, ymax = grid.world_bounds()
    shade = np.where(grid.data >= 65, 0.0, np.where(grid.data < 0, 0.6, 1.0))
    fig, ax = plt.subplots(figsize=(8, 6.5))
    ax.imshow(shade, cmap="gray", origin="lower", extent=(xmin, xmax, ymin, ymax), vmin=0, vmax=1)
    for i, plan in summary["plans"]:
        xy = np.asarray(plan)
        ax.plot(xy[:, 0], xy[:, 1], "--", lw=1.2, label=f"plan to goal {i + 1}")
    driven = np.asarray(summary["driven"])
    if len(driven):
        ax.plot(driven[:, 0], driven[:, 1], "-", color="tab:red", lw=2, label="driven")
    for gx, gy in GOALS:
        ax.plot(gx, gy, "*", ms=14, color="gold", mec="k")
    ax.set_title(f"point navigation: success={summary['success']} t={summary['time_s']} s "
                 f"length={summary['path_length_m']} m clearance>={summary['min_clearance_m']} m")
    ax.legend(loc="upper left", fontsize=8)
    fig.savefig(png, dpi=90)
    plt.close(fig)


# 5. Launch
launcher = Launcher()
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
launcher.kompass(components=[map_server, controller, planner, driver, local_mapper], multiprocessing=True)
launcher.add_pkg(components=[Mission()], package_name="mission", multiprocessing=True)

launcher.inputs(location=odom_topic)  # odometry for every navigation component
launcher.robot = my_robot  # also the simulated robot's shape and limits
launcher.frames = RobotFrames(world="map", odom="map", scan="LDS-01")
# The spec's web UI (the map, the plan and the robot in a browser; goals from the page): with
# EMOS_UI=1, open the link the run prints (docs/ui.md). Off by default: this recipe is the
# headless main job (CI, the tests, the chaos scenario), which must not need port 5001.
if os.environ.get("EMOS_UI") == "1":
    launcher.enable_ui(
        inputs=[planner.ui_main_action_input],
        outputs=[map_server.get_out_topic(TopicsKeys.GLOBAL_MAP), odom_topic, planner.get_out_topic(TopicsKeys.GLOBAL_PLAN)],
    )

summary_file = os.path.join(OUT_DIR, "summary.json")
if os.path.exists(summary_file):
    os.remove(summary_file)
launcher.bringup()
if not os.path.exists(summary_file):
    print("point navigation: the mission did not finish (no summary)", file=sys.stderr)
    sys.exit(1)
with open(summary_file) as f:
    result = json.load(f)
draw(result, os.path.join(OUT_DIR, "point_navigation.png"))
print(f"point navigation: {'SUCCESS' if result['success'] else 'FAILURE'} reached={result['reached']} "
      f"time={result['time_s']} s path={result['path_length_m']} m min_clearance={result['min_clearance_m']} m "
      f"collisions={int(result['collided'])}; picture: {os.path.join(OUT_DIR, 'point_navigation.png')}", flush=True)
sys.exit(0 if result["success"] else 1)
