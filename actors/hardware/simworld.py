"""The emulated Create 2 and RPLIDAR in the pybullet world: hardware in the loop without hardware.

:class:`SimulatedDevices` builds a :class:`emos.actors.sim.world.World` from a ROS map (the
Simulator's builder), puts a Create 2-sized cylinder robot in it and serves two byte-faithful
emulators on pseudo-terminals, reachable through stable links:

* :class:`PybulletCreate2`: the Create 2 emulator whose 15 ms tick moves the pybullet robot by
  its wheel speeds (the world steps in lockstep with the tick; a contact stops the body where
  it was, as the Simulator does, and the encoders then stand still) and whose bumper is pressed
  by what the body's front half has within 5 mm (pybullet closest points);
* an :class:`~.rplidar.emulator.RplidarEmulator` whose ranges are rays cast in that world from
  the robot's pose (``rayTestBatch``), at the emulator's real rate and resolution (10 Hz, 360
  nodes, the spin-up, start flags and quality bytes all as before).

The drivers cannot tell these ports from real devices. :class:`DevicesComponent` runs them as the
first component of a recipe (``recipes/hardware_navigation.py``), so they are up before the
plugins open their ports, and publishes the body's true pose for the recipe's referee only.
"""
from __future__ import annotations

import math
import os
from typing import Any

import numpy as np
from attrs import define, field

from emos.config import validators as V
from emos.config.base import BaseComponentConfig
from emos.core import clock
from emos.core.component import BaseComponent
from emos.geometry import quaternion_of_yaw
from emos.io.topic import Topic

from .create2 import protocol as P
from .create2.emulator import BUMPER_TRAVEL_M, Create2Emulator, bump_bits
from .rplidar.emulator import RplidarEmulator

__all__ = ["CREATE2_RADIUS", "DevicesComponent", "DevicesConfig", "PybulletCreate2", "SimulatedDevices"]

CREATE2_RADIUS = 0.17  # m: the Create 2's round body (OI spec: 34 cm across)
LIDAR_HEIGHT = 0.15  # m: an RPLIDAR on top of the body


def create2_spec() -> Any:
    from emos.actors.sim.robots import RobotSpec

    top = P.MAX_WHEEL_SPEED_MM_S / 1000.0
    # The emulator ramps the wheels itself (accel): the pybullet body follows each tick's twist
    # at once, so its limits are the wheels' and its accelerations unbounded in practice.
    return RobotSpec(name="create2", drive="differential", length=2 * CREATE2_RADIUS, width=2 * CREATE2_RADIUS,
                     radius=CREATE2_RADIUS, height=0.09, max_vx=top, max_omega=2 * top / P.WHEEL_BASE_M,
                     max_acc_x=1e3, max_acc_omega=1e4, lidar_height=LIDAR_HEIGHT, color=(0.3, 0.3, 0.3, 1.0))


class PybulletCreate2(Create2Emulator):
    """A Create 2 emulator whose body is a robot in a pybullet ``World`` (module docstring)."""

    def __init__(self, world: Any, robot: Any, **kwargs: Any) -> None:
        self.sim_world, self.robot = world, robot
        x, y, th = (float(v) for v in robot.pose)
        super().__init__(None, (x, y, th), radius=CREATE2_RADIUS, **kwargs)
        self._static = [b for b, name in world._body_names.items() if name not in ("ground",) and b != robot.body_id]

    def _advance(self, dr: float, dl: float, dt: float) -> tuple[float, float]:
        robot, world = self.robot, self.sim_world
        v, w = (dr + dl) / 2.0 / dt, (dr - dl) / P.WHEEL_BASE_M / dt
        robot.command(v, 0.0, w)
        before = robot.pose.copy()
        world.step()
        if not self._static:  # the static mesh is baked at the first step
            self._static = [b for b, name in world._body_names.items() if name == "static"]
        self.x, self.y, self.th = (float(c) for c in robot.pose)
        if robot.contacts or (np.allclose(robot.pose, before) and (dr or dl)):
            dr = dl = 0.0  # pushing into the obstacle: nothing moves, the encoders stand still
        client, near = world.client, []
        for body in self._static:
            for p in client.getClosestPoints(bodyA=robot.body_id, bodyB=body, distance=BUMPER_TRAVEL_M):
                near.append((p[5][0], p[5][1]))  # the point on the robot's body
        self.bumps = bump_bits(near, self.x, self.y, self.th)
        return dr, dl


class SimulatedDevices:
    """A pybullet world from ``map_yaml`` with the emulated Create 2 and RPLIDAR on it; the ports
    are ``base_link`` and ``lidar_link`` (symlinks to the ptys, stable across replugs)."""

    def __init__(self, map_yaml: str, pose: tuple[float, float, float] = (0.0, 0.0, 0.0), *, base_link: str,
                 lidar_link: str, rev_hz: float = 10.0, points_per_rev: int = 360, lidar_range: float = 12.0) -> None:
        from emos.actors.sim.builders import from_map
        from emos.actors.sim.clock import ClockMode, SimClock

        # Lockstep: the world advances only when the Create 2 emulator ticks (every 15 ms).
        self.world = from_map(map_yaml, clock=SimClock(dt=P.STREAM_PERIOD_S, mode=ClockMode.LOCKSTEP))
        self.robot = self.world.add_robot(create2_spec(), pose)
        self.base = PybulletCreate2(self.world, self.robot, link=base_link)
        self.lidar_range = float(lidar_range)
        self.lidar = RplidarEmulator(self.cast, pose, link=lidar_link, rev_hz=rev_hz,
                                     points_per_rev=points_per_rev, range_max=lidar_range)
        self.rays_cast = 0

    def cast(self, pose: tuple[float, float, float], bearings: np.ndarray) -> np.ndarray:
        """Ranges along ``bearings`` (sensor frame, counter-clockwise) from the robot's pose now
        (the emulator's own pose argument is ignored: the body is where pybullet has it)."""
        with self.base.lock:  # one pybullet client: never cast while the world steps
            x, y, th = (float(c) for c in self.robot.pose)
            angles = th + np.asarray(bearings, dtype=np.float64)
            n = len(angles)
            start, end = np.empty((n, 3)), np.empty((n, 3))
            start[:, 0], start[:, 1] = x, y
            end[:, 0], end[:, 1] = x + self.lidar_range * np.cos(angles), y + self.lidar_range * np.sin(angles)
            start[:, 2] = end[:, 2] = LIDAR_HEIGHT
            results = self.world.client.rayTestBatch(start, end, numThreads=1)
        self.rays_cast += n
        ids, _, fractions, _, _ = zip(*results)
        out = np.asarray(fractions, dtype=np.float64) * self.lidar_range
        out[np.asarray(ids) < 0] = np.inf
        return out

    def start(self) -> SimulatedDevices:
        self.base.start()
        self.lidar.start()
        return self

    def close(self) -> None:
        self.lidar.close()
        self.base.close()
        self.world.close()

    def truth(self) -> tuple[float, float, float]:
        with self.base.lock:
            x, y, th = (float(c) for c in self.robot.pose)
        return x, y, th

    @property
    def collided(self) -> bool:
        return bool(self.robot.collided)


@define(kw_only=True)
class DevicesConfig(BaseComponentConfig):
    """Where the emulated devices live: the map, the start pose and the two port links."""

    loop_rate: float = field(default=20.0, validator=V.finite_positive)  # ground-truth rate
    map_file: str = field(validator=V.non_empty_str)
    spawn: tuple = field(default=(0.0, 0.0, 0.0), converter=tuple)
    base_link: str = field(validator=V.non_empty_str)
    lidar_link: str = field(validator=V.non_empty_str)

    @spawn.validator
    def _check_spawn(self, attribute: Any, value: tuple) -> None:
        if len(value) != 3 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in value):
            raise ValueError(f"DevicesConfig.spawn: expected finite (x, y, yaw), got {value!r}")


class DevicesComponent(BaseComponent):
    """Runs :class:`SimulatedDevices` in its own process; publishes the body's true pose on
    ``truth`` (Odometry) for a referee. ``devices_status()`` says whether the body touched anything."""

    def __init__(self, component_name: str = "devices", config: DevicesConfig | None = None,
                 truth: Topic | None = None) -> None:
        self.truth_topic = truth or Topic(name="/sim/ground_truth", msg_type="Odometry")
        super().__init__(component_name, outputs=[self.truth_topic], config=config)
        self.config: DevicesConfig
        self.devices: SimulatedDevices | None = None

    @classmethod
    def config_class(cls) -> type[DevicesConfig]:
        return DevicesConfig

    def custom_on_activate(self) -> None:
        cfg = self.config
        for link in (cfg.base_link, cfg.lidar_link):
            os.makedirs(os.path.dirname(os.path.abspath(link)), exist_ok=True)
        self.devices = SimulatedDevices(cfg.map_file, tuple(float(v) for v in cfg.spawn),  # type: ignore[arg-type]
                                        base_link=cfg.base_link, lidar_link=cfg.lidar_link).start()
        self.get_logger().info("[%s] emulated Create 2 on %s, RPLIDAR on %s, in %s", self.component_name,
                               cfg.base_link, cfg.lidar_link, cfg.map_file)

    def custom_on_deactivate(self) -> None:
        devices, self.devices = self.devices, None
        if devices is not None:
            devices.close()

    custom_on_shutdown = custom_on_deactivate

    def _execution_step(self, **kwargs: Any) -> None:
        from emos.msgs.nav import Odometry

        devices = self.devices
        if devices is None:
            return
        x, y, th = devices.truth()
        msg = Odometry()
        msg.header.stamp = clock.stamp()
        msg.header.frame_id = "map"
        msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
        o = msg.pose.pose.orientation
        o.x, o.y, o.z, o.w = quaternion_of_yaw(th)
        msg.twist.twist.linear.x = (devices.base.v_right + devices.base.v_left) / 2.0
        self.publish(self.truth_topic, msg)
        self.health_status.set_healthy()

    def devices_status(self) -> dict:
        devices = self.devices
        if devices is None:
            return {"running": False}
        return {"running": True, "collided": devices.collided, "truth": list(devices.truth()),
                "ticks": devices.base.ticks, "revolutions": devices.lidar.revolutions_sent, "bumps": devices.base.bumps}
