"""Point navigation of a ROS 2 robot: recipes/point_navigation.py with the robot on the ROS 2 side.

    python recipes/ros2/diff_drive_robot.py --domain 7 &        # the robot: a plain rclpy program
    emos run recipes/point_navigation_ros2.py --ros2 --ros2-topics /odom,/scan,/cmd_vel --ros-domain-id 7
    ROS_DOMAIN_ID=7 emos run recipes/point_navigation_ros2.py   # the same: the recipe asks for the bridge itself

The navigation stack of point_navigation.py (MapServer, Planner, Controller with Pure Pursuit on
the LocalMapper's grid, DriveManager with safety zones) runs as it does there, without the
Simulator: the robot is whatever speaks ROS 2 on the domain, here or on the network, as a real
TurtleBot3's drivers do. Its only interface is ROS 2: ``/cmd_vel`` (geometry_msgs/Twist) in,
``/odom`` (nav_msgs/Odometry) and ``/scan`` (sensor_msgs/LaserScan) out; the run's ROS 2 bridge
(emos.interop.ros2) carries the three, and nothing else of the run goes on the graph unless
``--ros2-topics`` says so. recipes/ros2/diff_drive_robot.py is such a robot (a differential base
and a lidar ray-cast in the same map).

The robot's odometry must be in the map's frame (it starts where the map's frame starts, at
(0, 0, 0), as in point_navigation.py); there is no localizer here. A small ``Mission``
component sends the goals (``$EMOS_NAV_GOALS``, ``"x,y;x,y"``, default the two goals of
point_navigation.py), prints progress once a second, and ends the run: ``summary.json`` in
``$EMOS_NAV_OUT`` (default ``./point_navigation_ros2_out``), exit code 0 only when every goal was
reached within ``$EMOS_NAV_TIMEOUT`` s (default 240). Collisions are the robot's to judge (it is
the world); the summary gives the least clearance between the driven path and the map.
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
from emos.config.base import BaseComponentConfig
from emos.msgs import Header, Point, PointStamped
from emos.packages import get_package_share_directory
from emos.transport.select import use_ros2

map_file = os.path.join(get_package_share_directory(package_name="kompass_sim"), "maps", "turtlebot3_webots.yaml")
OUT_DIR = os.path.abspath(os.environ.get("EMOS_NAV_OUT", "point_navigation_ros2_out"))
MISSION_TIMEOUT = float(os.environ.get("EMOS_NAV_TIMEOUT", "240"))
ROS2_TOPICS = ["/odom", "/scan", "/cmd_vel"]


def _goals(text: str) -> list:
    try:
        goals = [tuple(float(v) for v in part.split(",")) for part in text.split(";") if part.strip()]
    except ValueError:
        goals = []
    if not goals or any(len(g) != 2 or not all(map(math.isfinite, g)) for g in goals):
        sys.exit(f"point_navigation_ros2: $EMOS_NAV_GOALS must be 'x,y;x,y;...' in metres, got {text!r}")
    return goals


GOALS = _goals(os.environ.get("EMOS_NAV_GOALS", "1.5,-3.2;-0.2,2.4"))  # round the table, then past the armchair

# The bridge: `emos run --ros2 ...` asked for it already, or the recipe asks (domain $ROS_DOMAIN_ID).
if os.environ.get("EMOS_ROS2") != "1":
    print(f"point_navigation_ros2: {use_ros2(topics=ROS2_TOPICS)}", flush=True)

# 1. The robot (a TurtleBot-sized differential base), as in point_navigation.py
my_robot = RobotConfig(
    model_type=RobotType.DIFFERENTIAL_DRIVE,
    geometry_type=RobotGeometry.Type.CYLINDER,
    geometry_params=np.array([0.1, 0.3]),
    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.4, max_acc=1.5, max_decel=2.5),
    ctrl_omega_limits=AngularCtrlLimits(max_vel=0.4, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
)

# 2. The navigation stack of point_navigation.py (emos.actors.nav.stacks), unlocalized: the
# robot's odometry is its location. The robot's topics are ROS 2's names and types; /scan is
# every component's default sensor_data.
odom_topic = Topic(name="/odom", msg_type="Odometry")
stack = point_navigation_stack(my_robot, RobotFrames(world="map", odom="map", robot_base="base_link", scan="base_scan"),
                               map_file, odom=odom_topic, command=Topic(name="/cmd_vel", msg_type="Twist"))
planner = stack.planner
NAV_COMPONENTS = stack.component_names


class Mission(BaseComponent):
    """Sends the goals one after the other, prints progress, and ends the run with a summary."""

    def __init__(self) -> None:
        self.odom, self.reached = odom_topic, planner.get_out_topic(TopicsKeys.REACHED_END)
        self.goal = planner.get_in_topic(TopicsKeys.GOAL_POINT)
        self.statuses = [Topic(name=f"{name}/status", msg_type="ComponentStatus") for name in NAV_COMPONENTS]
        super().__init__(component_name="mission", inputs=[self.odom, self.reached, *self.statuses],
                         outputs=[self.goal], config=BaseComponentConfig(loop_rate=5.0))

    def custom_on_activate(self) -> None:
        from emos.actors.nav.maps import distance_map, load_map

        self.clearance_map = load_map(map_file)
        self.distance = distance_map(self.clearance_map)
        self.t0 = time.monotonic()
        self.index, self.results, self.driven = -1, [], []
        self.min_clearance = math.inf
        self.last_print = self.goal_sent_at = self.repeated_at = 0.0
        self.done = False

    def _send(self) -> None:
        x, y = GOALS[self.index]
        self.publish(self.goal, PointStamped(header=Header(frame_id="map"), point=Point(x=x, y=y)))

    def _execution_step(self) -> None:
        self.health_status.set_healthy()
        if self.done:
            return
        odom = self.get_input(self.odom)
        if odom is None:
            if time.monotonic() - self.last_print >= 5.0:
                self.last_print = time.monotonic()
                print("[mission] waiting for /odom from ROS 2 (is the robot running on this ROS domain?)", flush=True)
            return
        now = time.monotonic()
        if self.index < 0:
            self.t0 = now  # the mission starts with the robot, not with the run
            self._next(now)
        p = odom.pose.pose.position
        pose = (p.x, p.y)
        if not self.driven or math.dist(self.driven[-1], pose) > 0.01:
            self.driven.append(pose)
        cell = self.clearance_map.world_to_grid(np.array(pose))
        if self.clearance_map.in_bounds(cell):
            self.min_clearance = min(self.min_clearance, float(self.distance[cell[1], cell[0]]) - my_robot.radius)
        goal = GOALS[self.index]
        left = math.dist(pose, goal)
        if now - self.repeated_at >= 2.0:  # a restarted Planner starts without a goal: repeat it
            self.repeated_at = now
            self._send()
        if now - self.last_print >= 1.0:
            self.last_print = now
            health = " ".join(f"{t.name.split('/')[1]}={self._health(t)}" for t in self.statuses)
            print(f"[mission] t={now - self.t0:5.1f}s goal {self.index + 1}: {left:5.2f} m left, "
                  f"{odom.twist.twist.linear.x:4.2f} m/s | {health}", flush=True)
        reached = self.get_input(self.reached)
        if reached is not None and reached.data and left <= 0.3 and self.input_age(self.reached) < now - self.goal_sent_at + 1e-3:
            self.results.append({"goal": goal, "reached": True, "time_s": round(now - self.goal_sent_at, 1)})
            print(f"[mission] goal {self.index + 1} reached in {now - self.goal_sent_at:.1f} s", flush=True)
            if self.index + 1 < len(GOALS):
                self._next(now)
            else:
                self._finish()
        elif now - self.t0 > MISSION_TIMEOUT:
            self.results.append({"goal": goal, "reached": False, "time_s": round(now - self.goal_sent_at, 1)})
            print(f"[mission] time limit of {MISSION_TIMEOUT:.0f} s: goal {self.index + 1} not reached", flush=True)
            self._finish()

    def _next(self, now: float) -> None:
        self.index += 1
        self.goal_sent_at = self.repeated_at = now
        self._send()
        print(f"[mission] goal {self.index + 1}/{len(GOALS)}: ({GOALS[self.index][0]:.2f}, {GOALS[self.index][1]:.2f})", flush=True)

    def _health(self, topic: Topic) -> str:
        msg = self.get_input(topic)
        return "?" if msg is None else ("ok", "ALGO", "COMP", "SYS", "gen")[min(int(msg.status), 4)]

    def _finish(self) -> None:
        from emos.core import control

        self.done = True
        reached = [r["reached"] for r in self.results] + [False] * (len(GOALS) - len(self.results))
        summary = {"reached": reached, "success": all(reached), "goals": self.results, "time_s": round(time.monotonic() - self.t0, 1),
                   "path_length_m": round(float(sum(math.dist(a, b) for a, b in zip(self.driven, self.driven[1:]))), 2),
                   "min_clearance_m": None if math.isinf(self.min_clearance) else round(self.min_clearance, 3)}
        os.makedirs(OUT_DIR, exist_ok=True)
        with open(os.path.join(OUT_DIR, "summary.json"), "w") as f:
            json.dump(dict(summary, driven=self.driven), f)
        print("[mission] " + json.dumps(summary), flush=True)
        control.call(os.environ["EMOS_SUPERVISOR_SOCKET"], control.SUPERVISOR_STOP, {"reason": "mission finished"}, timeout=5.0)


# 3. Launch: the navigation stack (with its robot and frames) and the Mission; the bridge is
# added by the run option
launcher = Launcher()
stack.launch(launcher)
launcher.add_pkg(components=[Mission()], package_name="mission", multiprocessing=True)

summary_file = os.path.join(OUT_DIR, "summary.json")
if os.path.exists(summary_file):
    os.remove(summary_file)
launcher.bringup()
if not os.path.exists(summary_file):
    print("point navigation (ROS 2 robot): the mission did not finish (no summary)", file=sys.stderr)
    sys.exit(1)
with open(summary_file) as f:
    result = json.load(f)
print(f"point navigation (ROS 2 robot): {'SUCCESS' if result['success'] else 'FAILURE'} reached={result['reached']} "
      f"time={result['time_s']} s path={result['path_length_m']} m min_clearance={result['min_clearance_m']} m", flush=True)
sys.exit(0 if result["success"] else 1)
