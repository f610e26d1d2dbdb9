"""Point navigation in the spec's TurtleBot3 arena: the spec's point-navigation recipe, ported.

    emos run recipes/point_navigation.py          # or: python recipes/point_navigation.py
    EMOS_UI=1 emos run recipes/point_navigation.py   # and watch it in the web UI

The navigation stack of the spec (MapServer, Planner, Controller with Pure Pursuit on the
LocalMapper's grid, DriveManager with safety zones) drives the robot in the spec's map, the
TurtleBot3 Webots arena (``turtlebot3_webots.yaml`` in the ``kompass_sim`` share directory),
which the ``Simulator`` (pybullet, headless) builds from the same file in place of Webots: to a
first goal round the table in front of the robot, then to a second one past the armchair at the
other end of the room.

The stack localizes as a real robot must (docs/localization.md, "In the main job"): the
Simulator gives its realistic, drifting odometry (wheel encoders with a per-run scale error and
2 % slip, heading from a gyro with a per-run bias), the ``Localizer`` corrects it against the
map and publishes ``map -> odom`` on ``/tf``, and ``MapFramePose`` composes the two into the
pose in the map frame that every navigation component reads (``/odometry/localized``). The
Simulator's true pose goes to the Mission only, which scores the localization against it.
``EMOS_NAV_LOCALIZE=0`` gives the stack the Simulator's true pose instead (no Localizer);
``EMOS_NAV_SEED`` picks the Simulator's noise (default 0).

Goals and progress come from a small ``Mission`` component defined here, so that the run needs
nobody at the web UI and judges itself: it publishes each goal on the planner's ``goal_point``
topic, prints progress once a second (distance left, speed, every component's health), and when
the robot arrives (``reached_end``) sends the next goal. At the end it writes ``summary.json`` and the
recipe draws ``point_navigation.png`` (map, plans, driven path). The summary's
``localization`` holds the error of the stack's pose against the truth, sampled 5 times a
second: ``position_m`` and ``heading_deg`` as ``{p50, p95, max}``, and ``odometry_drift_m`` (how
far the odometry alone was off at the end). Exit code 0 only when both
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
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotFrames, RobotGeometry, RobotType
from emos.actors.nav.components import TopicsKeys
from emos.actors.nav.stacks import point_navigation_stack
from emos.actors.sim import Simulator, SimulatorConfig
from emos.config.base import BaseComponentConfig
from emos.msgs import Header, Odometry, Point, PointStamped
from emos.packages import get_package_share_directory

kompass_sim_dir = get_package_share_directory(package_name="kompass_sim")
map_file = os.path.join(kompass_sim_dir, "maps", "turtlebot3_webots.yaml")

OUT_DIR = os.path.abspath(os.environ.get("EMOS_NAV_OUT", "point_navigation_out"))
GOALS = [(1.5, -3.2), (-0.2, 2.4)]  # round the table, then up the room past the armchair
MISSION_TIMEOUT = float(os.environ.get("EMOS_NAV_TIMEOUT", "240"))
# The stack localizes with the Localizer (Monte Carlo localization on the map) on the
# Simulator's drifting wheel + IMU odometry; EMOS_NAV_LOCALIZE=0 gives it the Simulator's
# ground-truth pose instead (the recipe before the Localizer existed).
LOCALIZE = os.environ.get("EMOS_NAV_LOCALIZE", "1") != "0"
SEED = int(os.environ.get("EMOS_NAV_SEED", "0"))  # the Simulator's noise (odometry scale error, gyro bias) and the Localizer's
# Localized, odometry is its own frame (odom -> base_link) and the Localizer publishes map ->
# odom; unlocalized, the odometry is the true pose and its frame is the map's.
FRAMES = RobotFrames(world="map", odom="odom" if LOCALIZE else "map", scan="LDS-01")

# 1. Robot configuration (the spec's TurtleBot-sized robot)
my_robot = RobotConfig(
    model_type=RobotType.DIFFERENTIAL_DRIVE,
    geometry_type=RobotGeometry.Type.CYLINDER,
    geometry_params=np.array([0.1, 0.3]),
    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.4, max_acc=1.5, max_decel=2.5),
    ctrl_omega_limits=AngularCtrlLimits(max_vel=0.4, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
)

# 2. The simulated robot and arena, built from the same map (instead of Webots); the robot
# starts where the map's frame starts, as in Webots. Localized: the Simulator's realistic
# odometry (wheel encoders with a per-run scale error and 2 % slip, heading from a gyro with a
# per-run bias: it drifts like a real base's); its true pose goes out on /sim/ground_truth for
# the Mission's score only, never to the stack.
odom_topic = Topic(name="/odometry/filtered", msg_type="Odometry")  # the base's odometry (odom -> base_link)
truth_topic = Topic(name="/sim/ground_truth", msg_type="Odometry")  # the referee's truth
realistic = {"odometry_mode": "wheel-imu", "slip": 0.02, "seed": SEED} if LOCALIZE else {}
sim = Simulator("sim", config=SimulatorConfig(world=map_file, spawn=(0.0, 0.0, 0.0), **realistic))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=odom_topic, ground_truth=truth_topic)
if LOCALIZE:
    # The Simulator's own transform tree holds map -> odom made from the truth (a perfect
    # localizer): off /tf, where the Localizer's map -> odom goes.
    sim.outputs(tf=Topic(name="/sim/tf", msg_type="TFMessage"))

# 3. The navigation stack (emos.actors.nav.stacks): MapServer on the spec's map of the arena,
# Planner, Controller with Pure Pursuit on the LocalMapper's 3 x 3 m grid, DriveManager with
# safety zones on /cmd_vel (no ROS distributions here: Twist). Localized (the ROS 2 way), it also
# runs the Localizer, which corrects the odometry against the map and publishes map -> odom on
# /tf (and its estimate on /amcl_pose), and MapFramePose, which composes that transform with each
# odometry message (odom -> base_link), as tf2 does for a Nav2 node, into the robot's pose in the
# map frame on /odometry/localized: the ``location`` every navigation component reads.
# Unlocalized, the odometry is the truth in the map frame and is the location itself.
stack = point_navigation_stack(my_robot, FRAMES, map_file, odom=odom_topic, command=Topic(name="/cmd_vel", msg_type="Twist"),
                               localize=LOCALIZE, initial_pose=sim.config.spawn, seed=SEED)
planner, map_server, location_topic = stack.planner, stack.map_server, stack.location
NAV_COMPONENTS = stack.component_names  # the stack's components, whose health the Mission prints


class Mission(BaseComponent):
    """Sends the goals one after the other, prints progress, and ends the run with a summary."""

    def __init__(self) -> None:
        # The referee's truth for progress, the driven path and the clearance; the stack's
        # location (what the navigation components believe) to score the localization.
        self.truth, self.location, self.odom = truth_topic, location_topic, odom_topic
        self.reached = planner.get_out_topic(TopicsKeys.REACHED_END)
        self.plan = planner.get_out_topic(TopicsKeys.GLOBAL_PLAN)
        self.goal = planner.get_in_topic(TopicsKeys.GOAL_POINT)
        self.statuses = [Topic(name=f"{name}/status", msg_type="ComponentStatus") for name in NAV_COMPONENTS]
        inputs = [self.truth, self.location, self.odom] if LOCALIZE else [self.truth, self.location]
        super().__init__(component_name="mission", inputs=[*inputs, self.reached, self.plan, *self.statuses],
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
        self.loc_errors: list = []  # (position m, heading deg) of the stack's location against the truth
        self.last_location = None
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
        self.loc_errors = state.get("loc_errors", [])
        self.resumed = True
        print(f"[mission] restarted: resuming at goal {self.index + 1}/{len(GOALS)}", flush=True)
        if 0 <= self.index < len(GOALS):  # the planner may have lost the goal too (it may have been killed with us)
            x, y = GOALS[self.index]
            self.publish(self.goal, PointStamped(header=Header(frame_id="map"), point=Point(x=x, y=y)))

    def _save(self) -> None:
        state = {"t0": self.t0, "index": self.index, "goal_sent_at": getattr(self, "goal_sent_at", self.t0),
                 "results": self.results, "driven": self.driven, "plans": self.plans,
                 "min_clearance": None if math.isinf(self.min_clearance) else self.min_clearance,
                 "loc_errors": self.loc_errors}
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
        truth = self.get_input(self.truth)
        if truth is None:
            return  # the simulator is starting
        if self.index < 0:
            self._send_next()
        p = truth.pose.pose.position
        pose = (p.x, p.y)
        self._score_location(truth)
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
            speed = truth.twist.twist.linear.x
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

    def _score_location(self, truth: Odometry) -> None:
        """One sample of the localization error: the newest location against the truth at its
        stamp (the truth, published every physics tick, carried over the few ms between the two
        stamps with its own twist)."""
        from emos.geometry import integrate_pose, wrap_angle

        loc = self.get_input(self.location)
        if loc is None or loc is self.last_location:
            return  # none yet (the Localizer starting), or no new one since the last sample
        self.last_location = loc
        q, t = truth.pose.pose, truth.twist.twist
        dt = loc.header.stamp.to_sec() - truth.header.stamp.to_sec()
        if abs(dt) > 0.5:
            return  # stamps too far apart to compare (a stalled publisher): no sample
        x, y, yaw = integrate_pose((q.position.x, q.position.y, q.orientation.yaw()), (t.linear.x, t.linear.y, t.angular.z), dt)
        e = loc.pose.pose
        self.loc_errors.append((round(math.hypot(e.position.x - x, e.position.y - y), 4),
                                round(abs(math.degrees(wrap_angle(e.orientation.yaw() - yaw))), 3)))

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
            "localization": localization_summary(self.loc_errors),
        }
        odom, truth = self.get_input(self.odom), self.get_input(self.truth)
        if LOCALIZE and odom is not None and truth is not None:
            # What the odometry alone would have believed at the end (both frames start at the spawn).
            a, b = odom.pose.pose.position, truth.pose.pose.position
            summary["localization"]["odometry_drift_m"] = round(math.hypot(a.x - b.x, a.y - b.y), 3)
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


def localization_summary(errors: list) -> dict:
    """p50 / p95 / max of the location's error against the truth, in metres and degrees."""
    out: dict = {"source": "localizer" if LOCALIZE else "ground truth", "samples": len(errors)}
    if errors:
        arr = np.asarray(errors, dtype=np.float64)
        for name, col, digits in (("position_m", 0, 3), ("heading_deg", 1, 2)):
            p50, p95 = np.percentile(arr[:, col], [50, 95])
            out[name] = {"p50": round(float(p50), digits), "p95": round(float(p95), digits), "max": round(float(arr[:, col].max()), digits)}
    return out


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


# 4. Launch: the Simulator, the stack (its navigation and localization packages, the location
# wiring, the robot's shape and limits, also the simulated robot's, and its frames), the Mission
launcher = Launcher()
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
stack.launch(launcher)
launcher.add_pkg(components=[Mission()], package_name="mission", multiprocessing=True)
# The spec's web UI (the map, the plan and the robot in a browser; goals from the page): with
# EMOS_UI=1, open the link the run prints (docs/ui.md). Off by default: this recipe is the
# headless main job (CI, the tests, the chaos scenario), which must not need port 5001.
if os.environ.get("EMOS_UI") == "1":
    launcher.enable_ui(
        inputs=[planner.ui_main_action_input],
        outputs=[map_server.get_out_topic(TopicsKeys.GLOBAL_MAP), location_topic, planner.get_out_topic(TopicsKeys.GLOBAL_PLAN)],
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
loc = result["localization"]
loc_text = (f"localization ({loc['source']}) error p50/p95/max {loc['position_m']['p50']}/{loc['position_m']['p95']}/"
            f"{loc['position_m']['max']} m, {loc['heading_deg']['p50']}/{loc['heading_deg']['p95']}/{loc['heading_deg']['max']} deg"
            if loc["samples"] else f"localization ({loc['source']}): no sample")
print(f"point navigation: {'SUCCESS' if result['success'] else 'FAILURE'} reached={result['reached']} "
      f"time={result['time_s']} s path={result['path_length_m']} m min_clearance={result['min_clearance_m']} m "
      f"collisions={int(result['collided'])}; {loc_text}; picture: {os.path.join(OUT_DIR, 'point_navigation.png')}", flush=True)
sys.exit(0 if result["success"] else 1)
