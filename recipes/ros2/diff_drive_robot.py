"""A ROS 2 robot for EMOS to drive: a plain rclpy program (not an EMOS component) that simulates a
differential-drive base and its 2D lidar in a ROS map_server map.

    python recipes/ros2/diff_drive_robot.py                     # the TurtleBot3 Webots arena, domain $ROS_DOMAIN_ID
    python recipes/ros2/diff_drive_robot.py --map my_map.yaml --domain 7 --x 0.5 --y -1 --yaw 1.57
    emos run recipes/point_navigation_ros2.py                   # beside it: EMOS's navigation stack drives it

Its only interface is ROS 2, as a real base's driver and lidar driver would offer it:

* subscribes ``/cmd_vel`` (``geometry_msgs/msg/Twist``); the wheels follow it within the
  acceleration limits; a command older than ``--cmd-timeout`` s stops the base (as real bases do);
* publishes ``/odom`` (``nav_msgs/msg/Odometry``, frame ``odom`` -> ``base_link``) at ``--odom-rate``
  Hz, the odom -> base_link transform on ``/tf`` when ``tf2_msgs`` is importable (it is not among
  the Jazzy wheels on PyPI: then it says so once and publishes no /tf), and ``/scan``
  (``sensor_msgs/msg/LaserScan``, frame ``base_scan`` at the base's centre, sensor-data QoS) at
  ``--scan-rate`` Hz, ray-cast in the map;
* stamps everything with its own ROS clock (wall time), as drivers do.

The world is the map's occupied cells (``occupied_thresh``); odometry is exact and its frame is
the map's (the robot starts at ``--x --y --yaw`` in map coordinates). It checks itself for
collisions: a step that would put an occupied cell under its disc (``--radius``) is refused (the
base stops, as against a wall) and counted. It prints ``ready``, then once a second ``pose X Y
YAW V W collisions N``, and at exit ``summary {json}``.

It uses EMOS only, when installed, to load the ROS 2 wheels' libraries (no LD_LIBRARY_PATH) and
to find the default map; with a sourced ROS 2 and ``--map`` it runs without EMOS.
"""
from __future__ import annotations

import argparse
import array
import importlib
import json
import math
import os
import sys
import time

import numpy as np


def load_map(yaml_path: str) -> tuple[np.ndarray, float, tuple[float, float]]:
    """``(occupied[row, col] with row 0 at the bottom, resolution, origin xy)`` of a map_server map
    (YAML + binary PGM, P5). Only the keys a map_server map needs; anything else is an error naming it."""
    import yaml

    with open(yaml_path) as f:
        meta = yaml.safe_load(f)
    if not isinstance(meta, dict) or not {"image", "resolution", "origin"} <= set(meta):
        raise ValueError(f"{yaml_path}: a map_server YAML needs image, resolution and origin, got {meta!r}")
    image = os.path.join(os.path.dirname(os.path.abspath(yaml_path)), meta["image"])
    with open(image, "rb") as f:
        data = f.read()
    fields: list[bytes] = []
    pos = 0
    while len(fields) < 4:  # magic, width, height, maxval; '#' comments between them
        while data[pos:pos + 1].isspace():
            pos += 1
        if data[pos:pos + 1] == b"#":
            pos = data.index(b"\n", pos) + 1
            continue
        end = pos
        while not data[end:end + 1].isspace():
            end += 1
        fields.append(data[pos:end])
        pos = end
    if fields[0] != b"P5":
        raise ValueError(f"{image}: expected a binary PGM (P5), got {fields[0]!r}")
    width, height, maxval = int(fields[1]), int(fields[2]), int(fields[3])
    if maxval > 255:
        raise ValueError(f"{image}: 16-bit PGM is not supported (maxval {maxval})")
    pixels = np.frombuffer(data, np.uint8, count=width * height, offset=pos + 1).reshape(height, width)
    occ = (255 - pixels.astype(np.float32)) / 255.0
    if meta.get("negate", 0):
        occ = 1.0 - occ
    occupied = occ > float(meta.get("occupied_thresh", 0.65))
    return np.ascontiguousarray(occupied[::-1]), float(meta["resolution"]), (float(meta["origin"][0]), float(meta["origin"][1]))


class World:
    """The map's occupied cells: ray casting and the robot's disc check."""

    def __init__(self, yaml_path: str, beams: int, range_max: float):
        self.occupied, self.res, self.origin = load_map(yaml_path)
        self.range_max = range_max
        self.angles = -math.pi + (2 * math.pi / beams) * np.arange(beams)
        # March each ray in half-cell steps: 360 x 400 samples for a 10 m range, a few ms.
        self.steps = np.arange(self.res / 2, range_max, self.res / 2)

    def _cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        col = np.floor((x - self.origin[0]) / self.res).astype(np.int64)
        row = np.floor((y - self.origin[1]) / self.res).astype(np.int64)
        inside = (row >= 0) & (row < self.occupied.shape[0]) & (col >= 0) & (col < self.occupied.shape[1])
        return np.where(inside, row, 0), np.where(inside, col, 0), inside

    def scan(self, x: float, y: float, yaw: float) -> np.ndarray:
        a = self.angles + yaw
        px = x + np.outer(np.cos(a), self.steps)
        py = y + np.outer(np.sin(a), self.steps)
        row, col, inside = self._cells(px, py)
        hit = inside & self.occupied[row, col]
        first = np.argmax(hit, axis=1)
        any_hit = hit[np.arange(len(a)), first]
        return np.where(any_hit, self.steps[first], np.inf).astype(np.float32)  # no echo: +inf (REP 117)

    def collides(self, x: float, y: float, radius: float) -> bool:
        span = np.arange(-radius, radius + self.res, self.res / 2)
        dx, dy = np.meshgrid(span, span)
        disc = dx * dx + dy * dy <= radius * radius
        row, col, inside = self._cells(x + dx[disc], y + dy[disc])
        return bool((inside & self.occupied[row, col]).any())


def _default_map() -> str:
    try:
        from emos.packages import get_package_share_directory

        return os.path.join(get_package_share_directory("kompass_sim"), "maps", "turtlebot3_webots.yaml")
    except ImportError:
        sys.exit("diff_drive_robot: EMOS is not installed here; give the map with --map FILE.yaml")


def _import_ros(packages: list[str]):
    """rclpy and the message modules; through EMOS's loader when EMOS is there (the pip wheels
    need it), else as a sourced ROS 2 provides them."""
    try:
        from emos.interop.ros2 import env
    except ImportError:
        env = None
    if env is not None:
        env.ensure_loadable()
        for package in packages:
            try:
                env.prepare_package(package)
            except Exception:  # noqa: BLE001 - the import below says what is missing
                pass
    import rclpy

    return rclpy


def _yaw_quaternion(yaw: float) -> tuple[float, float]:
    return math.sin(yaw / 2), math.cos(yaw / 2)


def _toward(value: float, target: float, up: float, down: float, dt: float) -> float:
    """``value`` moved toward ``target`` by at most the acceleration (speeding up) or deceleration
    (slowing down, toward zero) times ``dt``."""
    limit = (down if abs(target) < abs(value) or value * target < 0 else up) * dt
    return value + max(-limit, min(limit, target - value))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--map", default=None, help="map_server YAML (default: kompass_sim's turtlebot3_webots.yaml)")
    p.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0), help="ROS 2 domain id (default $ROS_DOMAIN_ID, else 0)")
    p.add_argument("--x", type=float, default=0.0)
    p.add_argument("--y", type=float, default=0.0)
    p.add_argument("--yaw", type=float, default=0.0)
    p.add_argument("--radius", type=float, default=0.1, help="the base's disc, for the collision check (m)")
    p.add_argument("--max-v", type=float, default=0.5, help="m/s")
    p.add_argument("--max-w", type=float, default=2.0, help="rad/s")
    p.add_argument("--acc-v", type=float, default=1.5, help="m/s^2 speeding up")
    p.add_argument("--dec-v", type=float, default=2.5, help="m/s^2 slowing down")
    p.add_argument("--acc-w", type=float, default=3.0, help="rad/s^2")
    p.add_argument("--scan-rate", type=float, default=10.0, help="Hz (10-20 as a TurtleBot's LDS)")
    p.add_argument("--odom-rate", type=float, default=20.0, help="Hz")
    p.add_argument("--beams", type=int, default=360)
    p.add_argument("--range-max", type=float, default=10.0, help="m")
    p.add_argument("--cmd-timeout", type=float, default=0.5, help="s without /cmd_vel before the base stops")
    args = p.parse_args(argv)
    if not 0 <= args.domain <= 232:
        p.error(f"--domain must be in 0..232, got {args.domain}")
    for name in ("scan_rate", "odom_rate", "radius", "max_v", "max_w", "acc_v", "dec_v", "acc_w", "range_max", "cmd_timeout"):
        if not getattr(args, name) > 0:
            p.error(f"--{name.replace('_', '-')} must be positive, got {getattr(args, name)}")

    world = World(args.map or _default_map(), args.beams, args.range_max)
    if world.collides(args.x, args.y, args.radius):
        p.error(f"the start ({args.x}, {args.y}) puts the robot's {args.radius} m disc on an occupied cell of the map")

    rclpy = _import_ros(["geometry_msgs", "nav_msgs", "sensor_msgs", "tf2_msgs"])
    from geometry_msgs.msg import TransformStamped, Twist
    from nav_msgs.msg import Odometry
    from rclpy.qos import QoSProfile, qos_profile_sensor_data
    from sensor_msgs.msg import LaserScan

    try:
        TFMessage = importlib.import_module("tf2_msgs.msg").TFMessage
    except ImportError:
        TFMessage = None
        print("diff_drive_robot: tf2_msgs is not importable by rclpy (not among the Jazzy wheels on PyPI): no /tf; "
              "/odom carries the pose", flush=True)

    rclpy.init(domain_id=args.domain)
    node = rclpy.create_node("diff_drive_robot")
    state = {"x": args.x, "y": args.y, "yaw": args.yaw, "v": 0.0, "w": 0.0, "cmd": (0.0, 0.0), "cmd_at": -math.inf,
             "collisions": 0, "blocked": False, "path_m": 0.0, "cmds": 0, "t": time.monotonic()}

    def on_cmd(msg: Twist) -> None:
        state["cmd"] = (max(-args.max_v, min(args.max_v, msg.linear.x)), max(-args.max_w, min(args.max_w, msg.angular.z)))
        state["cmd_at"] = time.monotonic()
        state["cmds"] += 1

    def step() -> None:
        now = time.monotonic()
        dt = min(now - state["t"], 0.1)  # a late timer (a loaded machine) does not teleport the base
        state["t"] = now
        target_v, target_w = state["cmd"] if now - state["cmd_at"] <= args.cmd_timeout else (0.0, 0.0)
        v = _toward(state["v"], target_v, args.acc_v, args.dec_v, dt)
        w = _toward(state["w"], target_w, args.acc_w, args.acc_w, dt)
        yaw = state["yaw"] + w * dt
        x = state["x"] + v * math.cos(state["yaw"] + w * dt / 2) * dt
        y = state["y"] + v * math.sin(state["yaw"] + w * dt / 2) * dt
        if (x, y) != (state["x"], state["y"]) and world.collides(x, y, args.radius):
            if not state["blocked"]:  # one collision per contact, not one per step
                state["collisions"] += 1
                print(f"collision at {x:.2f} {y:.2f}", flush=True)
            state["blocked"] = True
            state["v"], state["w"] = 0.0, w
            state["yaw"] = math.atan2(math.sin(yaw), math.cos(yaw))
            return
        state["blocked"] = False
        state["path_m"] += math.hypot(x - state["x"], y - state["y"])
        state.update(x=x, y=y, yaw=math.atan2(math.sin(yaw), math.cos(yaw)), v=v, w=w)

    odom_pub = node.create_publisher(Odometry, "/odom", QoSProfile(depth=10))
    scan_pub = node.create_publisher(LaserScan, "/scan", qos_profile_sensor_data)
    tf_pub = node.create_publisher(TFMessage, "/tf", QoSProfile(depth=100)) if TFMessage is not None else None
    node.create_subscription(Twist, "/cmd_vel", on_cmd, QoSProfile(depth=10))

    def publish_odom() -> None:
        step()
        stamp = node.get_clock().now().to_msg()
        qz, qw = _yaw_quaternion(state["yaw"])
        odom = Odometry()
        odom.header.stamp, odom.header.frame_id, odom.child_frame_id = stamp, "odom", "base_link"
        odom.pose.pose.position.x, odom.pose.pose.position.y = state["x"], state["y"]
        odom.pose.pose.orientation.z, odom.pose.pose.orientation.w = qz, qw
        odom.twist.twist.linear.x, odom.twist.twist.angular.z = state["v"], state["w"]
        odom_pub.publish(odom)
        if tf_pub is not None:
            t = TransformStamped()
            t.header.stamp, t.header.frame_id, t.child_frame_id = stamp, "odom", "base_link"
            t.transform.translation.x, t.transform.translation.y = state["x"], state["y"]
            t.transform.rotation.z, t.transform.rotation.w = qz, qw
            tf_pub.publish(TFMessage(transforms=[t]))

    def publish_scan() -> None:
        step()
        ranges = world.scan(state["x"], state["y"], state["yaw"])
        scan = LaserScan()
        scan.header.stamp, scan.header.frame_id = node.get_clock().now().to_msg(), "base_scan"
        scan.angle_min = float(world.angles[0])
        scan.angle_increment = float(world.angles[1] - world.angles[0])
        scan.angle_max = float(world.angles[-1])
        scan.scan_time, scan.range_min, scan.range_max = 1.0 / args.scan_rate, 0.05, args.range_max
        scan.ranges = array.array("f", ranges.tobytes())
        scan_pub.publish(scan)

    def report() -> None:
        print(f"pose {state['x']:.3f} {state['y']:.3f} {state['yaw']:.3f} {state['v']:.2f} {state['w']:.2f} "
              f"collisions {state['collisions']}", flush=True)

    node.create_timer(1.0 / args.odom_rate, publish_odom)
    node.create_timer(1.0 / args.scan_rate, publish_scan)
    node.create_timer(1.0, report)
    print(f"ready: domain {args.domain}, /cmd_vel in; /odom, /scan{', /tf' if tf_pub else ''} out; "
          f"start ({args.x:.2f}, {args.y:.2f}, {args.yaw:.2f})", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, Exception):  # SIGINT / SIGTERM: rclpy shut the context down
        pass
    finally:
        print("summary " + json.dumps({"x": round(state["x"], 3), "y": round(state["y"], 3), "collisions": state["collisions"],
                                       "path_m": round(state["path_m"], 2), "cmds": state["cmds"]}), flush=True)
        # Destroyed explicitly: a participant left to the interpreter's exit keeps its Fast DDS
        # shared-memory files in /dev/shm.
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
