"""Hardware in the loop: the navigation stack drives an iRobot Create 2 with an RPLIDAR on top,
through the serial drivers (robot plugins), to two goals in the TurtleBot3 arena of the main job.

    emos run recipes/hardware_navigation.py                      # emulated devices in pybullet
    emos run recipes/hardware_navigation.py -- --base-port /dev/ttyUSB0 --lidar-port /dev/ttyUSB1
    emos run recipes/hardware_navigation.py -- --devices devices.yaml   # {base_port: ..., lidar_port: ...}
    emos run recipes/hardware_navigation.py -- --sim             # the same stack on the Simulator

By default the devices are emulated: a ``DevicesComponent`` (started first) builds the arena in
pybullet from the map, puts a Create 2-sized robot in it, and serves a byte-faithful Create 2 on
one pseudo-terminal (its wheel speeds move the pybullet robot) and a byte-faithful RPLIDAR on
another (it ray-casts the pybullet world at 10 Hz, 360 nodes). The ``Create2Base`` and
``Rplidar`` plugins open those ports as they would open ``/dev/ttyUSB0``: the stack gets
``/odom`` from the encoders and ``/scan`` from the lidar, and its ``/cmd_vel`` becomes Drive
Direct bytes. Nothing of the Simulator's topics is used. Given real ports, the same recipe drives
real devices (no emulator is started); ``--sim`` swaps the two plugins for the Simulator, which
takes and publishes the same keys (``command``, ``odom``, ``scan``): that is the one line in
``robot_components()`` below.

The stack is the main job's (recipes/point_navigation.py): MapServer, Planner, Controller (Pure
Pursuit on the LocalMapper's grid), DriveManager; the robot's shape and limits come from the
plugin's RobotConfig (a Create 2 is 34 cm across), slowed for the arena. The odometry is the
location: the robot starts where the map's frame starts (a real one must be put there; a
Localizer, as the main job uses, corrects drift on long runs). A ``HardwareMission`` sends the
goals, prints progress and ends the run; it writes ``summary.json`` to ``$EMOS_NAV_OUT``
(default ``./hardware_navigation_out``): goals reached, time, and (emulated) whether the body
touched anything. Exit code 0 only when both goals were reached without a collision.
"""
import argparse
import json
import math
import os
import shutil
import sys
import tempfile
import time

import attrs
import yaml

from emos import BaseComponent, Launcher, Topic
from emos.actors.hardware.create2.component import Create2Base, Create2Config
from emos.actors.hardware.rplidar.component import Rplidar, RplidarConfig
from emos.actors.hardware.simworld import DevicesComponent, DevicesConfig
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotFrames
from emos.actors.nav.components import TopicsKeys
from emos.actors.nav.stacks import point_navigation_stack
from emos.config.base import BaseComponentConfig
from emos.msgs import Header, Point, PointStamped
from emos.packages import get_package_share_directory

parser = argparse.ArgumentParser(prog="hardware_navigation", description=__doc__.split("\n")[0])
parser.add_argument("--base-port", help="the Create 2's serial port (default: an emulated one)")
parser.add_argument("--lidar-port", help="the RPLIDAR's serial port (default: an emulated one)")
parser.add_argument("--devices", help="a YAML file with base_port and lidar_port")
parser.add_argument("--sim", action="store_true", help="drive the Simulator instead of the plugins")
args, _ = parser.parse_known_args()
ports = {"base_port": args.base_port, "lidar_port": args.lidar_port}
if args.devices:
    with open(args.devices) as f:
        given = yaml.safe_load(f) or {}
    if not isinstance(given, dict) or set(given) - set(ports):
        sys.exit(f"hardware_navigation: {args.devices} must map base_port and/or lidar_port to device paths, got {given!r}")
    ports = {k: ports[k] or given.get(k) for k in ports}
if bool(ports["base_port"]) != bool(ports["lidar_port"]):
    sys.exit("hardware_navigation: give both --base-port and --lidar-port (real devices), or neither (emulated)")
EMULATED = not ports["base_port"] and not args.sim

map_file = os.path.join(get_package_share_directory("kompass_sim"), "maps", "turtlebot3_webots.yaml")
OUT_DIR = os.path.abspath(os.environ.get("EMOS_NAV_OUT", "hardware_navigation_out"))
GOALS = [(1.5, -3.2), (-0.2, 2.4)]  # the main job's: round the table, then up the room past the armchair
MISSION_TIMEOUT = float(os.environ.get("EMOS_NAV_TIMEOUT", "300"))
SPAWN = (0.0, 0.0, 0.0)
# The emulators' ports: stable links (as /dev/serial/by-id gives), removed at the end of the run.
LINKS_DIR = tempfile.mkdtemp(prefix="emos-hil-") if EMULATED else ""

# The robot: the plugin's RobotConfig (shape, wheel base), at the main job's speeds.
my_robot = attrs.evolve(Create2Base.robot_config(),
                        ctrl_vx_limits=LinearCtrlLimits(max_vel=0.3, max_acc=1.0, max_decel=1.5),
                        ctrl_omega_limits=AngularCtrlLimits(max_vel=0.6, max_acc=2.0, max_decel=2.0, max_steer=math.pi / 3))
cmd_topic = Topic(name="/cmd_vel", msg_type="Twist")
odom_topic = Topic(name="/odom", msg_type="Odometry")
scan_topic = Topic(name="/scan", msg_type="LaserScan")
truth_topic = Topic(name="/sim/ground_truth", msg_type="Odometry")  # the referee's, never the stack's


def robot_components() -> list:
    """What takes /cmd_vel and gives /odom and /scan: the plugins, or the Simulator (--sim)."""
    if args.sim:
        from emos.actors.sim import Simulator, SimulatorConfig

        sim = Simulator("sim", config=SimulatorConfig(world=map_file, spawn=SPAWN))
        sim.inputs(command=cmd_topic)
        sim.outputs(odom=odom_topic, scan=scan_topic, ground_truth=truth_topic)
        return [sim]
    base_port, lidar_port = ports["base_port"], ports["lidar_port"]
    devices = []
    if EMULATED:
        links = LINKS_DIR
        base_port, lidar_port = os.path.join(links, "create2"), os.path.join(links, "rplidar")
        devices = [DevicesComponent("devices", DevicesConfig(map_file=map_file, spawn=SPAWN, base_link=base_port,
                                                             lidar_link=lidar_port), truth=truth_topic)]
    base = Create2Base("base", Create2Config(port=base_port, frame_id="map"))  # odometry from the spawn = map frame
    base.inputs(command=cmd_topic)
    base.outputs(odom=odom_topic)
    lidar = Rplidar("lidar", RplidarConfig(port=lidar_port))
    lidar.outputs(scan=scan_topic)
    return [*devices, base, lidar]


# The main job's navigation stack (emos.actors.nav.stacks), on the plugins' topics: the odometry
# is the location (no Localizer), the lidar's /scan feeds the LocalMapper, Controller and
# DriveManager, and the DriveManager's /cmd_vel goes to the base.
stack = point_navigation_stack(my_robot, RobotFrames(world="map", odom="map", scan="laser"), map_file,
                               odom=odom_topic, scan=scan_topic, command=cmd_topic)
planner = stack.planner


class HardwareMission(BaseComponent):
    """Sends each goal (again every 2 s: a restarted Planner starts without one), prints progress
    once a second, and ends the run with summary.json when both are reached or time is up."""

    def __init__(self) -> None:
        self.truth = truth_topic if (EMULATED or args.sim) else odom_topic
        self.reached = planner.get_out_topic(TopicsKeys.REACHED_END)
        self.goal = planner.get_in_topic(TopicsKeys.GOAL_POINT)
        super().__init__(component_name="mission", inputs=[self.truth, self.reached], outputs=[self.goal],
                         config=BaseComponentConfig(loop_rate=5.0))

    def custom_on_activate(self) -> None:
        self.t0 = time.monotonic()
        self.index, self.results, self.done, self.last_print, self.sent_at = -1, [], False, 0.0, 0.0
        self.driven: list = []

    def _send(self) -> None:
        x, y = GOALS[self.index]
        self.sent_at = time.monotonic()
        self.publish(self.goal, PointStamped(header=Header(frame_id="map"), point=Point(x=x, y=y)))

    def _execution_step(self) -> None:
        truth = self.get_input(self.truth)
        if self.done or truth is None:
            return
        if self.index < 0:
            self.index, self.goal_t0 = 0, time.monotonic()
            self._send()
            print(f"[mission] goal 1/{len(GOALS)}: {GOALS[0]}", flush=True)
        p = truth.pose.pose.position
        if not self.driven or math.dist(self.driven[-1], (p.x, p.y)) > 0.02:
            self.driven.append((round(p.x, 3), round(p.y, 3)))
        now, goal = time.monotonic(), GOALS[self.index]
        left = math.dist((p.x, p.y), goal)
        if now - self.sent_at >= 2.0:
            self._send()
        if now - self.last_print >= 1.0:
            self.last_print = now
            print(f"[mission] t={now - self.t0:5.1f}s goal {self.index + 1}: {left:5.2f} m left", flush=True)
        reached = self.get_input(self.reached)
        if reached is not None and reached.data and left <= 0.3 and self.input_age(self.reached) < now - self.goal_t0:
            self.results.append({"goal": goal, "reached": True, "time_s": round(now - self.goal_t0, 1)})
            print(f"[mission] goal {self.index + 1} reached in {now - self.goal_t0:.1f} s", flush=True)
            if self.index + 1 < len(GOALS):
                self.index, self.goal_t0 = self.index + 1, now
                self._send()
                print(f"[mission] goal {self.index + 1}/{len(GOALS)}: {GOALS[self.index]}", flush=True)
            else:
                self._finish()
        elif now - self.t0 > MISSION_TIMEOUT:
            self.results.append({"goal": goal, "reached": False, "time_s": round(now - self.goal_t0, 1)})
            self._finish()
        self.health_status.set_healthy()

    def _finish(self) -> None:
        from emos.core import control

        self.done = True
        collided = False
        if EMULATED:
            collided = bool(control.ControlClient("devices", self.node.ctx, timeout=5.0).execute_method("devices_status").get("collided"))
        reached = [r["reached"] for r in self.results] + [False] * (len(GOALS) - len(self.results))
        summary = {"reached": reached, "goals": self.results, "time_s": round(time.monotonic() - self.t0, 1),
                   "collided": collided, "emulated": EMULATED, "sim": args.sim, "driven": self.driven,
                   "success": all(reached) and not collided}
        os.makedirs(OUT_DIR, exist_ok=True)
        with open(os.path.join(OUT_DIR, "summary.json"), "w") as f:
            json.dump(summary, f)
        print("[mission] " + json.dumps({k: v for k, v in summary.items() if k != "driven"}), flush=True)
        control.call(os.environ["EMOS_SUPERVISOR_SOCKET"], control.SUPERVISOR_STOP, {"reason": "mission finished"}, timeout=5.0)


launcher = Launcher()
launcher.add_pkg(components=robot_components(), package_name="robot", multiprocessing=True)  # devices first: ports up before the plugins open them
stack.launch(launcher)  # the stack, its robot and frames
launcher.add_pkg(components=[HardwareMission()], package_name="mission", multiprocessing=True)

summary_file = os.path.join(OUT_DIR, "summary.json")
if os.path.exists(summary_file):
    os.remove(summary_file)
try:
    launcher.bringup()
finally:
    if LINKS_DIR:
        shutil.rmtree(LINKS_DIR, ignore_errors=True)
if not os.path.exists(summary_file):
    print("hardware navigation: the mission did not finish (no summary)", file=sys.stderr)
    sys.exit(1)
with open(summary_file) as f:
    result = json.load(f)
print(f"hardware navigation: {'SUCCESS' if result['success'] else 'FAILURE'} reached={result['reached']} "
      f"time={result['time_s']} s collided={result['collided']} ({'emulated devices' if result['emulated'] else 'Simulator' if result['sim'] else 'real devices'})",
      flush=True)
sys.exit(0 if result["success"] else 1)
