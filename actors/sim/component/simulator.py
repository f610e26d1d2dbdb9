"""``Simulator``: a pybullet robot that stands in for Webots, Gazebo or the real robot in a recipe.

    sim = Simulator(component_name="sim", config=SimulatorConfig(world="house", robot="turtlebot3"))
    sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
    sim.outputs(odom=Topic(name="/odometry/filtered", msg_type="Odometry"),
                camera=Topic(name="/image_raw/compressed", msg_type="CompressedImage"))

Keys and default topics (``None``: off until the recipe gives a topic):

=================== ============================================ ==============================
key                 message types                                default
=================== ============================================ ==============================
command (in)        Twist, TwistStamped, TwistArray              /cmd_vel (Twist)
joint_command (in)  JointState, JointTrajectory (the arm)        None
odom                Odometry                                     /odom
scan                LaserScan                                    /scan
tf                  TFMessage                                    /tf
clock               Clock                                        /clock
camera              Image (rgb8) or CompressedImage (JPEG)       None
depth               Image (32FC1, metres)                        None
camera_info         CameraInfo                                   None
depth_camera_info   CameraInfo                                   None
rgbd                RGBD                                         None
map                 OccupancyGrid                                None
ground_truth        Odometry (true pose, world frame, each tick) None
joint_states        JointState (the arm)                         None
wrist_camera        Image or CompressedImage (the arm)           None
=================== ============================================ ==============================

``ground_truth`` (off by default) is the robot's true pose and velocity in ``frames.world``
after every physics tick, for a referee or an evaluation harness, never for the robot's stack.

Frames come from ``config.frames`` (``launcher.frames`` sets it at bringup): odometry is
``frames.odom -> frames.robot_base``, the scan is stamped ``frames.scan``, the camera
``frames.rgb`` and depth ``frames.depth``; ``/tf`` carries world -> odom -> base -> sensors.

The physics runs in a thread of this component's process (see ``physics.py``); the Timed
step reports its health. A command older than ``command_timeout`` stops the robot. In the
``tabletop`` world there is an arm instead of a mobile base: ``camera`` is the front camera,
and the arm holds its last joint targets (a position-controlled arm's safe behaviour).
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from emos.core.keyed import AllowedTopic, KeyedComponent
from emos.io.topic import Topic

from .config import SimulatorConfig
from .physics import PhysicsLoop
from .worlds import SimSetup, build_setup

CAMERA_KEYS = ("camera", "depth", "camera_info", "depth_camera_info", "rgbd")


class Simulator(KeyedComponent):
    """A simulated robot in a simulated world, publishing its sensors and obeying commands."""

    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "command": AllowedTopic(types=("Twist", "TwistStamped", "TwistArray"),
                                default=Topic(name="/cmd_vel", msg_type="Twist")),
        "joint_command": AllowedTopic(types=("JointState", "JointTrajectory")),
    }
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "odom": AllowedTopic(types=("Odometry",), default=Topic(name="/odom", msg_type="Odometry")),
        "scan": AllowedTopic(types=("LaserScan",), default=Topic(name="/scan", msg_type="LaserScan")),
        "tf": AllowedTopic(types=("TFMessage",), default=Topic(name="/tf", msg_type="TFMessage")),
        "clock": AllowedTopic(types=("Clock",), default=Topic(name="/clock", msg_type="Clock")),
        "camera": AllowedTopic(types=("Image", "CompressedImage")),
        "depth": AllowedTopic(types=("Image",)),
        "camera_info": AllowedTopic(types=("CameraInfo",)),
        "depth_camera_info": AllowedTopic(types=("CameraInfo",)),
        "rgbd": AllowedTopic(types=("RGBD",)),
        "map": AllowedTopic(types=("OccupancyGrid",)),
        # For referees and evaluation harnesses only: the robot's true pose. A navigation
        # stack must not subscribe to it (a real robot has no such topic).
        "ground_truth": AllowedTopic(types=("Odometry",)),
        "joint_states": AllowedTopic(types=("JointState",)),
        "wrist_camera": AllowedTopic(types=("Image", "CompressedImage")),
    }

    def __init__(self, component_name: str, config: SimulatorConfig | None = None, **kwargs: Any) -> None:
        super().__init__(component_name, config=config, **kwargs)
        self.config: SimulatorConfig
        self.setup: SimSetup | None = None
        self.physics: PhysicsLoop | None = None

    @classmethod
    def config_class(cls) -> type[SimulatorConfig]:
        return SimulatorConfig

    # -- lifecycle -------------------------------------------------------------------------------
    def custom_on_configure(self) -> None:
        self.config.check_rates()
        wanted = self._wanted_outputs()
        if self.config.lockstep_consumers and "clock" not in wanted:
            raise ValueError(f"Simulator {self.component_name!r}: lockstep_consumers {self.config.lockstep_consumers} "
                             "answer /clock ticks, but the clock output was removed; give it a topic")
        self.setup = build_setup(self.config, want_scan="scan" in wanted,
                                 want_camera=any(k in wanted for k in CAMERA_KEYS), want_wrist="wrist_camera" in wanted)
        log, name = self.get_logger(), self.component_name
        robot = self.setup.robot
        if robot is not None:
            spec = robot.spec
            log.info("[%s] world %r, robot %s (%s, %.2f x %.2f m) at %s, clock %s", name, self.config.world, spec.name,
                     spec.drive.value, spec.length, spec.width, tuple(round(float(v), 3) for v in robot.pose),
                     self.config.clock_mode.value)
        else:
            log.info("[%s] world %r with the arm (joints %s), clock %s", name, self.config.world,
                     ", ".join(self.setup.arm.names), self.config.clock_mode.value)
        silent = [k for k in wanted if k in (("odom", "scan", "tf") if robot is None else ("joint_states", "wrist_camera"))]
        if robot is not None and self.get_in_topic("joint_command") is not None:
            silent.append("joint_command (input)")
        if silent:
            log.warning("[%s] world %r has no %s: %s stay silent", name, self.config.world,
                        "mobile base" if robot is None else "arm", ", ".join(silent))

    def custom_on_activate(self) -> None:
        assert self.setup is not None, "configure builds the world before activate"
        wanted = self._wanted_outputs()
        topics = {key: topic for key in wanted if (topic := self.get_out_topic(key)) is not None}  # all: wanted ones have a topic
        inputs = {key: self.get_in_topic(key) for key in self.allowed_inputs}
        map_grid = self._map_grid() if "map" in wanted else None

        def publish(key: str, msg: Any) -> None:
            self.publish(topics[key], msg)

        self.physics = PhysicsLoop(self.component_name, self.config, self.setup, self.node.ctx, inputs,
                                   {k: t.msg_type for k, t in topics.items()}, publish, map_grid)
        self.physics.start()

    def custom_on_deactivate(self) -> None:
        self._stop_physics()

    def custom_on_shutdown(self) -> None:
        self._stop_physics()
        self._close_world()

    def custom_on_cleanup(self) -> None:
        self._close_world()

    def custom_on_error(self) -> bool:
        self._stop_physics()
        self._close_world()
        return True

    def _execution_step(self, **kwargs: Any) -> None:
        physics = self.physics
        if physics is None:
            self.health_status.set_healthy()
            return
        if physics.error is not None:
            self.health_status.set_fail_component(component_names=[self.component_name],
                                                  message=f"physics stopped: {type(physics.error).__name__}: {physics.error}")
        elif not physics.is_alive():
            self.health_status.set_fail_component(component_names=[self.component_name], message="physics thread is not running")
        else:
            self.health_status.set_healthy()

    # -- helpers ---------------------------------------------------------------------------------
    def _wanted_outputs(self) -> list[str]:
        return [key for key in self.allowed_outputs if self.get_out_topics(key)]

    def _map_grid(self) -> Any:
        """The map this world was built from (a ROS map, the shipped house map) or, for worlds
        built from shapes, their rasterization at 5 cm."""
        from emos.actors.nav.maps import OccupancyGridMap, load_map

        from ..data import HOUSE_MAP
        from ..rasterize import shapes_to_grid

        world = self.config.world
        if world in ("house", "house_person"):
            return load_map(HOUSE_MAP)
        if world.endswith((".yaml", ".yml")):
            return load_map(world)
        assert self.setup is not None
        xmin, ymin, xmax, ymax = self.setup.world.bounds(margin=1.0)
        res = 0.05
        size = (int((ymax - ymin) / res) + 1, int((xmax - xmin) / res) + 1)
        occupied = shapes_to_grid(self.setup.world.shapes, res, (xmin, ymin), size)
        return OccupancyGridMap(data=(occupied * 100).astype("int8"), resolution=res, origin=(xmin, ymin, 0.0))

    def _stop_physics(self) -> None:
        if self.physics is not None:
            self.physics.stop()
            self.physics = None

    def _close_world(self) -> None:
        if self.setup is not None:
            self.setup.world.close()
            self.setup = None

    # -- introspection (for tests, benchmarks and `emos` CLI's execute_method) --------------------
    def sim_status(self) -> dict:
        """Simulated time, clock ticks, messages published per key, robot pose, moving obstacles' poses, wait time."""
        physics, setup = self.physics, self.setup
        out: dict = {"running": physics is not None and physics.is_alive()}
        if setup is not None:
            out["sim_time"] = setup.world.clock.now()
            if setup.world.movers:  # where each moving obstacle (a walking person, ...) is now
                now = setup.world.clock.now()
                out["movers"] = [{"name": getattr(m, "name", type(m).__name__), "pose": list(m.pose_at(now))}
                                 for m in setup.world.movers]
            if setup.robot is not None:
                out["pose"] = [float(v) for v in setup.robot.pose]
                out["collided"] = bool(setup.robot.collided)
                if setup.robot.first_contacts:  # where it first touched: (x, y) of up to 8 contact points
                    out["contacts"] = [[float(c.position[0]), float(c.position[1])] for c in setup.robot.first_contacts[:8]]
            if setup.arm is not None:
                out["joints"] = dict(zip(setup.arm.names, setup.arm.joint_state()[1].tolist()))
        if physics is not None:
            out.update(clock_ticks=physics.clock_ticks, published=dict(physics.published),
                       commands=physics.follower.received, lockstep_wait_s=physics.waited_s)
            if physics.charge is not None:  # compute_deadline: what the stack's compute time cost
                out["compute"] = physics.charge.stats()
        return out
