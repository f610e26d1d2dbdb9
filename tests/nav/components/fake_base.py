"""A kinematic robot base for component tests, run as a component of the recipe under test.

It is the test's stand-in for hardware (the pybullet Simulator lives on another branch):
integrates the velocity it receives on ``/cmd_vel``, and publishes ``/odom`` and a 360-beam
``/scan`` of a rectangular room with box obstacles (exact ray-box intersections). Creating the
file named by ``$FAKE_BASE_FREEZE_ODOM`` stops the odometry (to test stale input).
"""
from __future__ import annotations

import math
import os

import numpy as np

from emos import BaseComponent, Topic
from emos import msgs as M
from emos.config.base import BaseComponentConfig

ROOM = (0.0, 0.0, 6.0, 4.0)  # xmin, ymin, xmax, ymax
BOXES = [(2.8, 0.0, 3.2, 2.6)]  # a wall from the bottom: the way goes round its top end


def ray_boxes(ox: float, oy: float, angles: np.ndarray, boxes, rmax: float = 10.0) -> np.ndarray:
    dx, dy = np.cos(angles), np.sin(angles)
    best = np.full(angles.shape, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for (x0, y0, x1, y1) in boxes:
            tx0, tx1 = (x0 - ox) / dx, (x1 - ox) / dx
            ty0, ty1 = (y0 - oy) / dy, (y1 - oy) / dy
            tmin = np.maximum(np.minimum(tx0, tx1), np.minimum(ty0, ty1))
            tmax = np.minimum(np.maximum(tx0, tx1), np.maximum(ty0, ty1))
            hit = (tmax >= np.maximum(tmin, 0)) & np.isfinite(tmin)
            t = np.where(tmin > 0, tmin, tmax)  # inside the box (the room): the exit
            best = np.where(hit & (t > 0) & (t < best), t, best)
    best[best > rmax] = np.inf
    return best


class FakeBase(BaseComponent):
    def __init__(self, start=(1.0, 1.0, 0.0), rate: float = 20.0, fov_deg: float = 360.0) -> None:
        """``fov_deg``: the laser's field of view, centred ahead (a Jackal's is 270)."""
        super().__init__(
            component_name="base",
            inputs=[Topic(name="/cmd_vel", msg_type="Twist")],
            outputs=[Topic(name="/odom", msg_type="Odometry"), Topic(name="/scan", msg_type="LaserScan")],
            config=BaseComponentConfig(loop_rate=rate),
        )
        self.start = start
        self.fov = math.radians(fov_deg)

    def custom_on_activate(self) -> None:
        self.pose = np.array(self.start, dtype=float)

    def _execution_step(self) -> None:
        dt = 1.0 / self.config.loop_rate
        cmd = self.get_input("/cmd_vel")
        v = w = 0.0
        if cmd is not None and (self.input_age("/cmd_vel") or 1.0) < 0.5:
            v, w = cmd.linear.x, cmd.angular.z
        x, y, th = self.pose
        self.pose = np.array([x + v * math.cos(th) * dt, y + v * math.sin(th) * dt, th + w * dt])
        odom, scan = base_messages(self.pose, v, w, self.fov)
        freeze = os.environ.get("FAKE_BASE_FREEZE_ODOM")
        if not (freeze and os.path.exists(freeze)):
            self.publish("/odom", odom)
        self.publish("/scan", scan)
        self.health_status.set_healthy()


class CommandFollower:
    """A kinematic base in lockstep with a ``ComponentHarness``: :meth:`move`, called before each
    tick, drives ``pose`` by the newest command on ``command`` for the time since the last call
    (exact arcs, ``emos.geometry.integrate_pose``) and returns that command (v, w)."""

    def __init__(self, start, command: str = "/cmd_vel"):
        self.pose = np.array(start, dtype=float)
        self.command = command
        self.last_time: float | None = None

    def move(self, h) -> tuple[float, float]:
        from emos.geometry import integrate_pose

        cmd = h.latest(self.command)
        v, w = (cmd.linear.x, cmd.angular.z) if cmd is not None else (0.0, 0.0)
        dt = 0.0 if self.last_time is None else h.time - self.last_time
        self.last_time = h.time
        self.pose = integrate_pose(self.pose, (v, 0.0, w), dt)
        return v, w


def base_messages(pose, v: float, w: float, fov: float, boxes=BOXES) -> tuple[M.Odometry, M.LaserScan]:
    """What the base at ``pose`` (x, y, yaw), moving at ``v`` m/s and ``w`` rad/s, publishes:
    odometry in the map frame, and a 360-beam scan of the room and ``boxes`` over ``fov`` (rad)
    centred ahead."""
    odom = M.Odometry()
    odom.header.frame_id = "map"
    odom.pose.pose.position.x, odom.pose.pose.position.y = float(pose[0]), float(pose[1])
    odom.pose.pose.orientation = M.Quaternion.from_yaw(float(pose[2]))
    odom.twist.twist.linear.x, odom.twist.twist.angular.z = float(v), float(w)
    angles = -0.5 * fov + np.arange(360) * (fov / 360)
    r = ray_boxes(pose[0], pose[1], angles + pose[2], [ROOM, *boxes])
    scan = M.LaserScan(angle_min=-0.5 * fov, angle_max=0.5 * fov - fov / 360, angle_increment=fov / 360,
                       range_min=0.05, range_max=10.0, ranges=r.astype(np.float32))
    return odom, scan


def write_room_map(path) -> str:
    """The same room as a map_server YAML/PGM at 5 cm (walls 10 cm thick inside the room)."""
    from emos.actors.nav.maps import OccupancyGridMap, save_map

    res = 0.05
    rows, cols = int(ROOM[3] / res), int(ROOM[2] / res)
    data = np.zeros((rows, cols), dtype=np.int8)
    data[:2, :] = data[-2:, :] = 100
    data[:, :2] = data[:, -2:] = 100
    for (x0, y0, x1, y1) in BOXES:
        data[int(y0 / res):int(math.ceil(y1 / res)), int(x0 / res):int(math.ceil(x1 / res))] = 100
    return str(save_map(OccupancyGridMap(data=data, resolution=res, origin=(0.0, 0.0, 0.0)), path))
