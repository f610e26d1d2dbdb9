"""The World: one pybullet physics client holding obstacles, robots and sensors, and a clock.

Several Worlds can coexist in one process: each owns its own ``BulletClient`` and passes
it everywhere, so nothing touches pybullet's implicit default client.
"""
from __future__ import annotations

import logging
import math
import os
import threading
from collections.abc import Iterable
from typing import Any, TypeVar

import numpy as np

from . import _deps
from .body import SimRobot
from .clock import ClockMode, SimClock
from .moving import MovingObstacle
from .primitives import Box, Cylinder, Shape, Wall, shapes_to_mesh
from .robots import RobotSpec, robot_spec
from .sensors.base import Sensor

log = logging.getLogger(__name__)

SensorT = TypeVar("SensorT", bound=Sensor)


def _reach(shape: Shape) -> float:
    """How far a moving shape extends from its path."""
    if isinstance(shape, Cylinder):
        return shape.radius / math.cos(math.pi / 16) + 0.01
    return math.hypot(*getattr(shape, "size", (0.0, 0.0))) / 2 + 0.01


class World:
    """A headless (DIRECT) pybullet world; ``gui=True`` opens a window when a display exists.

    Static obstacles added with :meth:`add` are baked into one triangle mesh at the next tick
    (fast ray casts); moving obstacles, robots and sensors are updated every tick of ``clock``.
    ``seed`` fixes every random stream (noise of sensors and actuation), so two worlds built
    the same way with the same seed produce identical trajectories and readings.
    """

    def __init__(self, *, clock: SimClock | None = None, seed: int = 0, gui: bool = False,
                 ground: bool = True, name: str = "world") -> None:
        pb = _deps.pybullet()
        mode = pb.DIRECT
        if gui:
            if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
                mode = pb.GUI
            else:
                log.warning("World(gui=True) but no display is available: running headless (DIRECT)")
        with _deps.c_stdout_silenced():
            self.client = _deps.bullet_client()(connection_mode=mode)
        self.gui = mode == pb.GUI
        self.clock = clock if clock is not None else SimClock()
        self.seed = int(seed)
        self.name = name
        self.shapes: list[Shape] = []
        self.movers: list[MovingObstacle] = []
        self.robots: list[SimRobot] = []
        self.sensors: list[Sensor] = []
        self._pending: list[Shape] = []
        self._mover_bodies: list[int] = []
        self._body_names: dict[int, str] = {}
        self._next_due: list[float] = []
        # Extent (xmin, ymin, xmax, ymax) of everything static or scripted a ray can hit (see ray_bounds).
        self._hittable: np.ndarray | None = None
        self._streams = 0
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.RLock()
        self.ground_id: int | None = None
        # Set by the ready-made builders: a suggested robot pose, the BARN entry, the ROS map.
        self.spawn: tuple[float, float, float] | None = None
        self.barn: Any = None
        self.occupancy_map: Any = None
        self.dynamics = False  # see enable_dynamics()
        self.tick_hooks: list[Any] = []  # called with the stamp after every tick's physics (an arm's grasp)
        if ground:
            self.client.setAdditionalSearchPath(_deps.pybullet_data_path())
            self.ground_id = self.client.loadURDF("plane.urdf")
            self._body_names[self.ground_id] = "ground"

    # -- ready-made worlds (see builders.py) -----------------------------------------------
    @classmethod
    def demo_house(cls, **kwargs: Any) -> World:
        from .builders import demo_house

        return demo_house(**kwargs)

    @classmethod
    def from_map(cls, yaml_path: str, **kwargs: Any) -> World:
        from .builders import from_map

        return from_map(yaml_path, **kwargs)

    @classmethod
    def from_barn(cls, world: Any, worlds_file: str | None = None, **kwargs: Any) -> World:
        from .builders import from_barn

        return from_barn(world, worlds_file, **kwargs)

    # -- randomness --------------------------------------------------------------------------
    def rng(self) -> np.random.Generator:
        """A fresh generator, determined by the world seed and how many were handed out before."""
        self._streams += 1
        return np.random.default_rng([self.seed, self._streams])

    # -- building ----------------------------------------------------------------------------
    def add(self, item: Shape | MovingObstacle | Iterable[Shape]) -> None:
        """Add a static shape (Box, Cylinder, Wall), several, or a MovingObstacle."""
        if isinstance(item, MovingObstacle):
            self._add_mover(item)
        elif isinstance(item, (Box, Cylinder, Wall)):
            self.shapes.append(item)
            self._pending.append(item)
        elif isinstance(item, Iterable):
            for x in item:
                if not isinstance(x, (Box, Cylinder, Wall)):
                    raise TypeError(f"World.add expected Box, Cylinder or Wall items, got {type(x).__name__}")
                self.add(x)
        else:
            raise TypeError(f"World.add expected a Box, Cylinder, Wall, MovingObstacle or a list, got {type(item).__name__}")

    def add_box(self, center: tuple[float, float], size: tuple[float, float], height: float = 1.0, yaw: float = 0.0) -> Box:
        box = Box(center, size, height, yaw)
        self.add(box)
        return box

    def add_cylinder(self, center: tuple[float, float], radius: float, height: float = 1.0) -> Cylinder:
        cyl = Cylinder(center, radius, height)
        self.add(cyl)
        return cyl

    def add_wall(self, start: tuple[float, float], end: tuple[float, float], thickness: float = 0.1, height: float = 1.0) -> Wall:
        wall = Wall(start, end, thickness, height)
        self.add(wall)
        return wall

    def _add_mover(self, mover: MovingObstacle) -> None:
        if hasattr(mover, "create_body"):  # draws itself (a Person's billboard)
            body = mover.create_body(self.client)
        else:
            body = self._mover_body(mover)
        self.movers.append(mover)
        self._grow_hittable(mover.waypoints, _reach(mover.shape))
        self._mover_bodies.append(body)
        self._body_names[body] = mover.name
        self._place_movers()

    def _mover_body(self, mover: MovingObstacle) -> int:
        pb, c, shape = _deps.pybullet(), self.client, mover.shape
        if isinstance(shape, Box):
            half = [shape.size[0] / 2, shape.size[1] / 2, shape.height / 2]
            col = c.createCollisionShape(pb.GEOM_BOX, halfExtents=half)
            vis = c.createVisualShape(pb.GEOM_BOX, halfExtents=half, rgbaColor=list(shape.color))
        else:
            col = c.createCollisionShape(pb.GEOM_CYLINDER, radius=shape.radius, height=shape.height)
            vis = c.createVisualShape(pb.GEOM_CYLINDER, radius=shape.radius, length=shape.height, rgbaColor=list(shape.color))
        return c.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=col, baseVisualShapeIndex=vis)

    def _bake(self) -> None:
        """Turn pending static shapes into one mesh body per colour."""
        pb, c = _deps.pybullet(), self.client
        by_color: dict[tuple, list[Shape]] = {}
        for shape in self._pending:
            by_color.setdefault(shape.color, []).append(shape)
        for color, shapes in by_color.items():
            vertices, indices = shapes_to_mesh(shapes)
            self._grow_hittable(vertices[:, :2], 0.0)
            v, i = vertices.tolist(), indices.reshape(-1).tolist()
            col = c.createCollisionShape(pb.GEOM_MESH, vertices=v, indices=i, flags=pb.GEOM_FORCE_CONCAVE_TRIMESH)
            vis = c.createVisualShape(pb.GEOM_MESH, vertices=v, indices=i, rgbaColor=list(color))
            body = c.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=col, baseVisualShapeIndex=vis)
            self._body_names[body] = "static"
        self._pending = []

    def add_robot(self, spec: str | RobotSpec = "jackal", pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
                  name: str | None = None, slip: float = 0.0, actuation_noise: float = 0.0,
                  drive: Any = None) -> SimRobot:
        """``drive``: a drive model or its name (``ideal``, ``skid-steer``, ``wheeled``; see
        actors/sim/dynamics); None = the spec's default (``ideal`` for most presets)."""
        spec = robot_spec(spec)
        name = name or (spec.name if not any(r.name == spec.name for r in self.robots) else f"{spec.name}{len(self.robots)}")
        robot = SimRobot(self, spec, name, pose, slip=slip, actuation_noise=actuation_noise, rng=self.rng(), drive=drive)
        self.robots.append(robot)
        self._body_names[robot.body_id] = name
        return robot

    def add_sensor(self, sensor: SensorT) -> SensorT:
        """Attach ``sensor``; its first reading is taken at the next tick."""
        if sensor.robot is not None and sensor.robot not in self.robots:  # None: fixed in the world
            raise ValueError(f"sensor {sensor.name!r} rides on a robot that is not in this world")
        sensor.bind(self, self.rng())
        self.sensors.append(sensor)
        self._next_due.append(self.clock.now() + self.clock.dt)
        return sensor

    def enable_dynamics(self, gravity: float = -9.81, substeps: int = 4) -> None:
        """Integrate rigid-body dynamics every tick (table-top manipulation: an arm's motors,
        falling and grasped objects). Mobile bases stay kinematic: they are re-posed each tick."""
        self.client.setGravity(0.0, 0.0, gravity)
        self.client.setPhysicsEngineParameter(fixedTimeStep=self.clock.dt, numSubSteps=int(substeps))
        self.dynamics = True

    # -- stepping ----------------------------------------------------------------------------
    def _place_movers(self) -> None:
        t = self.clock.now()
        for mover, body in zip(self.movers, self._mover_bodies):
            x, y, heading = mover.pose_at(t)
            self.client.resetBasePositionAndOrientation(
                body, [x, y, mover.shape.height / 2], [0, 0, math.sin(heading / 2), math.cos(heading / 2)])

    def step(self, n: int = 1) -> list[tuple[Sensor, Any]]:
        """Advance ``n`` ticks; returns the (sensor, reading) pairs produced on the way."""
        out: list[tuple[Sensor, Any]] = []
        with self._lock:
            for _ in range(n):
                out.extend(self._tick())
        return out

    def _tick(self) -> list[tuple[Sensor, Any]]:
        if self._pending:
            self._bake()
        dt = self.clock.dt
        for robot in self.robots:
            robot.advance(dt)
        if self.dynamics:
            self.client.stepSimulation()
        stamp = self.clock.tick()
        for hook in self.tick_hooks:
            hook(stamp)
        self._place_movers()
        if self.robots:
            self.client.performCollisionDetection()
            for robot in self.robots:
                robot.resolve_contacts(stamp, self.client.getContactPoints(bodyA=robot.body_id), self._body_names)
        out = []
        for i, sensor in enumerate(self.sensors):
            sensor.on_tick(stamp)
            if stamp >= self._next_due[i] - 1e-9:
                out.append((sensor, sensor.publish(stamp)))
                period = 1.0 / sensor.rate_hz
                # A fixed schedule (no drift); periods shorter than a tick fire once per tick.
                self._next_due[i] += period
                if self._next_due[i] <= stamp + 1e-9:
                    self._next_due[i] = stamp + period
        return out

    def run_for(self, seconds: float) -> list[tuple[Sensor, Any]]:
        """Step for ``seconds`` of simulated time, paced according to the clock mode."""
        return self.step(int(round(seconds / self.clock.dt)))

    def start(self) -> None:
        """Step in a background thread until :meth:`stop` (realtime or fast clocks only)."""
        if self.clock.mode is ClockMode.LOCKSTEP:
            raise RuntimeError("World.start(): a lockstep clock only advances when the caller calls step()")
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._loop, name=f"{self.name}-stepper", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.is_set():
            self.step()

    def stop(self) -> None:
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            self._thread = None

    def close(self) -> None:
        self.stop()
        for robot in self.robots:
            robot.drive.close()  # a wheeled model's private physics client
        try:
            self.client.disconnect()
        except Exception:  # already disconnected
            pass

    def __enter__(self) -> World:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- queries -----------------------------------------------------------------------------
    def _grow_hittable(self, points: np.ndarray, reach: float) -> None:
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        if not len(pts):
            return
        box = np.r_[pts.min(axis=0) - reach, pts.max(axis=0) + reach]
        if self._hittable is None:
            self._hittable = box
        else:
            self._hittable = np.r_[np.minimum(self._hittable[:2], box[:2]), np.maximum(self._hittable[2:], box[2:])]

    def ray_bounds(self) -> np.ndarray | None:
        """(xmin, ymin, xmax, ymax) outside which a horizontal ray can hit nothing: static
        shapes, moving obstacles' paths and the robots where they are now (None: nothing).
        A lidar stops its rays there instead of at its range (a 30 m laser in a 10 m field
        costs 2-3x less; the readings are the same)."""
        if self._pending:
            self._bake()
        known = len(self._body_names) + sum(r.visual_id is not None for r in self.robots)
        if self.client.getNumBodies() != known:
            return None  # bodies added behind the World's back (an arm, its objects): no shortcut
        boxes = [] if self._hittable is None else [self._hittable]
        for robot in self.robots:
            r = robot.spec.circumscribed_radius + abs(robot.spec.center_offset)
            x, y = robot.pose[:2]
            boxes.append(np.array([x - r, y - r, x + r, y + r]))
        if not boxes:
            return None
        b = np.array(boxes)
        return np.r_[b[:, :2].min(axis=0), b[:, 2:].max(axis=0)]

    def bounds(self, margin: float = 0.5) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) around obstacles and robots."""
        pts = [s.footprint() for s in self.shapes]
        pts += [np.asarray(m.waypoints) for m in self.movers]
        pts += [np.asarray(r.trail) for r in self.robots]
        if not pts:
            return (-5.0, -5.0, 5.0, 5.0)
        allp = np.concatenate(pts)
        lo, hi = allp.min(axis=0) - margin, allp.max(axis=0) + margin
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])
