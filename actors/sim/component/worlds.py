"""Build the World a :class:`SimulatorConfig` names, with its robot and sensors."""
from __future__ import annotations

import math
from typing import Any

import attrs

from ..barn_worlds import BARN_START
from ..body import SimRobot
from ..builders import demo_house, from_barn, from_map
from ..clock import ClockMode, SimClock
from ..jackal import JACKAL_LASER, JACKAL_ODOMETRY
from ..sensors import Camera, CameraConfig, Lidar, LidarConfig, Odometry, OdometryConfig, WheelImuOdometry
from ..world import World
from .config import SimulatorConfig
from .robot_model import resolve_robot

EMPTY_SPAWN = (0.0, 0.0, 0.0)


@attrs.define(eq=False)
class SimSetup:
    """A built world: the robot or arm and the sensors the component publishes (None = not
    wanted, or not in this world: the table-top world has an arm and no mobile base)."""

    world: World
    robot: SimRobot | None
    odometry: Odometry | WheelImuOdometry | None
    lidar: Lidar | None
    camera: Camera | None
    arm: Any = None
    joints: Any = None
    wrist_camera: Camera | None = None


def build_world(cfg: SimulatorConfig) -> World:
    world = _named_world(cfg)
    if cfg.obstacles:
        world.add(cfg.obstacles)
    for mover in cfg.moving_obstacles:
        world.add(mover)
    return world


def _named_world(cfg: SimulatorConfig) -> World:
    # The component paces time itself (realtime sleeps, lockstep handshakes), so the world's
    # own clock never sleeps: its mode is lockstep, advanced tick by tick.
    clock = SimClock(dt=1.0 / cfg.physics_rate, mode=ClockMode.LOCKSTEP)
    kwargs: dict[str, Any] = {"clock": clock, "seed": cfg.seed}
    name = cfg.world
    if name == "house":
        return demo_house(**kwargs)
    if name == "house_person":
        from ..person import house_with_person

        return house_with_person(**kwargs)
    if name == "tabletop":
        from ..arm import tabletop_world

        return tabletop_world(**kwargs)
    if name == "empty":
        world = World(name="empty", **kwargs)
        world.spawn = EMPTY_SPAWN
        return world
    if name.startswith("dynabarn:"):
        from ..dynabarn import from_dynabarn

        return from_dynabarn(int(name.split(":", 1)[1]), **kwargs)
    if name.startswith("barn:"):
        world = from_barn(int(name.split(":", 1)[1]), worlds_file=cfg.barn_source, **kwargs)
        world.spawn = BARN_START
        return world
    world = from_map(name, **kwargs)
    if world.spawn is None:
        world.spawn = free_spawn(world)
    return world


def free_spawn(world: World) -> tuple[float, float, float]:
    """For a map without a suggested pose: the free cell farthest from any wall."""
    from emos.actors.nav.maps.edt import euclidean_distance_transform

    occ = world.occupancy_map
    dist = euclidean_distance_transform(occ.occupied, sampling=occ.resolution)
    row, col = divmod(int(dist.argmax()), dist.shape[1])
    ox, oy, oyaw = occ.origin
    lx, ly = (col + 0.5) * occ.resolution, (row + 0.5) * occ.resolution
    c, s = math.cos(oyaw), math.sin(oyaw)
    return (ox + c * lx - s * ly, oy + s * lx + c * ly, 0.0)


def _camera_config(cfg: SimulatorConfig, frame: str, near: float = 0.05) -> CameraConfig:
    return CameraConfig(width=cfg.camera_width, height=cfg.camera_height, vfov_deg=cfg.camera_vfov_deg,
                        rate_hz=cfg.camera_rate, frame_id=frame, near=near)


def build_setup(cfg: SimulatorConfig, want_scan: bool, want_camera: bool, want_wrist: bool = False) -> SimSetup:
    world = build_world(cfg)
    try:
        if getattr(world, "arm", None) is not None:
            return _arm_setup(cfg, world, want_camera, want_wrist)
        spawn = cfg.spawn or world.spawn or EMPTY_SPAWN
        robot = world.add_robot(resolve_robot(cfg.robot), spawn, slip=cfg.slip, actuation_noise=cfg.actuation_noise,
                                drive=cfg.drive)
        frames = cfg.frames
        odom = _odometry(cfg, robot)
        world.add_sensor(odom)
        lidar = None
        if want_scan:
            lidar = Lidar(robot, _lidar_config(cfg))
            world.add_sensor(lidar)
        camera = None
        if want_camera:
            camera = Camera(robot, _camera_config(cfg, frames.rgb))
            world.add_sensor(camera)
        return SimSetup(world, robot, odom, lidar, camera)
    except BaseException:
        world.close()
        raise


def _odometry(cfg: SimulatorConfig, robot: SimRobot) -> Odometry | WheelImuOdometry:
    frames = cfg.frames
    mode = cfg.odometry_mode or ("wheel" if cfg.odom_noise else "truth")
    if mode == "wheel-imu":
        return WheelImuOdometry(robot, attrs.evolve(JACKAL_ODOMETRY, rate_hz=cfg.odom_rate, frame_id=frames.odom,
                                                    child_frame_id=frames.robot_base))
    return Odometry(robot, OdometryConfig(rate_hz=cfg.odom_rate, noisy=mode == "wheel",
                                          frame_id=frames.odom, child_frame_id=frames.robot_base))


def _lidar_config(cfg: SimulatorConfig) -> LidarConfig:
    if cfg.scan_preset == "jackal":
        return attrs.evolve(JACKAL_LASER, frame_id=cfg.frames.scan)
    return LidarConfig(fov_deg=cfg.scan_fov_deg, beams=cfg.scan_beams, range_max=cfg.scan_range_max,
                       noise_std=cfg.scan_noise_std, rate_hz=cfg.scan_rate, frame_id=cfg.frames.scan)


def _arm_setup(cfg: SimulatorConfig, world: World, want_camera: bool, want_wrist: bool) -> SimSetup:
    from ..arm.arm import JointStateSensor, PosedCamera, wrist_camera_pose

    arm = world.arm  # type: ignore[attr-defined]
    joints = world.add_sensor(JointStateSensor(arm, cfg.joint_state_rate))
    camera = wrist = None
    if want_camera:
        pose = world.front_camera_pose  # type: ignore[attr-defined]
        camera = world.add_sensor(PosedCamera(lambda: pose, _camera_config(cfg, "front_camera", near=0.02), name="front"))
    if want_wrist:
        wrist = world.add_sensor(PosedCamera(lambda: wrist_camera_pose(arm), _camera_config(cfg, "wrist_camera", near=0.01),
                                             name="wrist"))
    return SimSetup(world, None, None, None, camera, arm=arm, joints=joints, wrist_camera=wrist)
