"""``SimulatorConfig``: which world, which robot, which sensors at which rates, noise, clock.

Every field is validated when it is set, so a recipe with an unknown world or robot, a map
file that does not exist or a negative rate fails where it is written, naming the field.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import attrs
from attrs import define, field

from emos.config import validators as V
from emos.config.base import BaseComponentConfig

from ..clock import ClockMode
from ..robots import PRESETS

# Named worlds; a path to a ROS map YAML, "barn:<index>" and "dynabarn:<index>" are accepted
# too (see worlds.py).
NAMED_WORLDS = ("house", "house_person", "empty", "tabletop")


def _frames_default() -> Any:
    from emos.actors.nav.robot import RobotFrames

    return RobotFrames()


def _frames(value: Any) -> Any:
    """A RobotFrames, or a mapping of its fields (config files)."""
    if isinstance(value, dict):
        from emos.actors.nav.robot import RobotFrames

        try:
            return RobotFrames(**value)
        except TypeError as exc:
            raise ValueError(f"SimulatorConfig.frames: {exc}") from None
    return value


def _check_frames(instance: Any, attribute: attrs.Attribute, value: Any) -> None:
    from emos.actors.nav.robot import RobotFrames

    if not isinstance(value, RobotFrames):
        raise TypeError(f"SimulatorConfig.frames must be a RobotFrames, got {type(value).__name__} {value!r}")


def check_world(instance: Any, attribute: attrs.Attribute, value: Any) -> None:
    """``house``, ``house_person``, ``empty``, ``tabletop`` (the arm), ``barn:<index>``,
    ``dynabarn:<index>`` or a ROS map YAML path."""
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"SimulatorConfig.world must be a world name or a map path, got {value!r}")
    if value in NAMED_WORLDS:
        return
    if value.startswith("barn:"):
        from ..barn_worlds import load_barn_worlds

        try:
            idx = int(value.split(":", 1)[1])
        except ValueError:
            raise ValueError(f"SimulatorConfig.world {value!r}: a BARN world is 'barn:<index>', e.g. 'barn:0'") from None
        source = getattr(instance, "barn_source", None)
        try:
            worlds = load_barn_worlds(source)
        except (FileNotFoundError, ValueError) as exc:
            raise ValueError(f"SimulatorConfig.world {value!r}: cannot read the BARN worlds "
                             f"(barn_source {source!r}): {exc}") from None
        if idx not in worlds:
            raise ValueError(f"SimulatorConfig.world {value!r}: no BARN world {idx} (indices {min(worlds)}..{max(worlds)})")
        return
    if value.startswith("dynabarn:"):
        from ..dynabarn import load_dynabarn

        try:
            idx = int(value.split(":", 1)[1])
        except ValueError:
            raise ValueError(f"SimulatorConfig.world {value!r}: a DynaBARN world is 'dynabarn:<index>', e.g. 'dynabarn:0'") from None
        entries = load_dynabarn()
        if idx not in entries:
            raise ValueError(f"SimulatorConfig.world {value!r}: no DynaBARN world {idx} (indices {min(entries)}..{max(entries)})")
        return
    if value.endswith((".yaml", ".yml")):
        from emos.actors.nav.maps.map_yaml import read_map_yaml

        path = Path(value).expanduser()
        if not path.is_file():
            raise ValueError(f"SimulatorConfig.world: map file {str(path)!r} does not exist")
        meta = read_map_yaml(path)  # a malformed YAML fails here, naming the file and key
        if not Path(meta["image"]).is_file():
            raise ValueError(f"SimulatorConfig.world: map {str(path)!r} names image {str(meta['image'])!r}, which does not exist")
        return
    raise ValueError(f"SimulatorConfig.world: unknown world {value!r}; expected one of {', '.join(NAMED_WORLDS)}, "
                     "'barn:<index>', 'dynabarn:<index>' or the path of a ROS map YAML")


def _barn_source(instance: Any, attribute: attrs.Attribute, value: Any) -> None:
    if value is None:
        return
    if not isinstance(value, str) or not Path(value).expanduser().exists():
        raise ValueError(f"SimulatorConfig.barn_source must be None or the path of a BARN worlds JSON file or "
                         f"repository clone, got {value!r}")


def _check_robot(instance: Any, attribute: attrs.Attribute, value: Any) -> None:
    from emos.actors.nav.robot import RobotConfig

    if isinstance(value, RobotConfig):
        return
    if not isinstance(value, str) or value not in PRESETS:
        raise ValueError(f"SimulatorConfig.robot: unknown robot {value!r}; expected one of {', '.join(sorted(PRESETS))} "
                         "or a RobotConfig")


def _optional_choice(*choices: str) -> Any:
    def check(instance: Any, attribute: attrs.Attribute, value: Any) -> None:
        if value is not None and value not in choices:
            raise ValueError(f"SimulatorConfig.{attribute.name} must be None or one of {', '.join(choices)}, got {value!r}")
    return check


def _spawn(value: Any) -> tuple[float, float, float] | None:
    if value is None:
        return None
    try:
        x, y, yaw = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"SimulatorConfig.spawn must be (x, y, yaw) or None, got {value!r}") from None
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise ValueError(f"SimulatorConfig.spawn must be finite, got {value!r}")
    return (x, y, yaw)


def _consumers(value: Any) -> list[str]:
    if isinstance(value, str) or not all(isinstance(v, str) and v for v in value):
        raise ValueError(f"SimulatorConfig.lockstep_consumers must be a list of component names, got {value!r}")
    return list(value)


def _obstacles(value: Any) -> list:
    from ..primitives import Box, Cylinder, Wall

    items = list(value)
    for item in items:
        if not isinstance(item, (Box, Cylinder, Wall)):
            raise ValueError(f"SimulatorConfig.obstacles must be Box, Cylinder or Wall objects, got {type(item).__name__} {item!r}")
    return items


def _movers(value: Any) -> list:
    from ..moving import MovingObstacle

    items = list(value)
    for item in items:
        if not isinstance(item, MovingObstacle):
            raise ValueError(f"SimulatorConfig.moving_obstacles must be MovingObstacle (or Person) objects, "
                             f"got {type(item).__name__} {item!r}")
    return items


@define(kw_only=True)
class SimulatorConfig(BaseComponentConfig):
    """Parameters of the :class:`Simulator`. Rates are in Hz of *simulated* time."""

    world: str = field(default="house", validator=check_world)
    barn_source: str | None = field(default=None, validator=_barn_source)
    """Where ``barn:<index>`` worlds come from: None = the 250 worlds shipped in the package,
    else a worlds JSON file or a clone of the BARN repository (all 300)."""
    robot: Any = field(default="jackal", validator=_check_robot)
    """A preset name, or a navigation ``RobotConfig`` (``launcher.robot`` sets it at bringup:
    the simulated robot is then the one navigation plans for, see ``robot_model.py``)."""
    spawn: tuple[float, float, float] | None = field(default=None, converter=_spawn)
    """Robot pose (x, y, yaw) in the world frame; None = the world's suggested spawn."""
    obstacles: list = field(factory=list, converter=_obstacles)
    """Extra static Box / Cylinder / Wall shapes added to the world (not to its map)."""
    moving_obstacles: list = field(factory=list, converter=_movers)
    """MovingObstacle / Person objects walking their waypoints in simulated time."""
    frames: Any = field(factory=_frames_default, converter=_frames, validator=_check_frames)
    """Frame names (``RobotFrames``); ``launcher.frames`` overrides them at bringup."""

    physics_rate: float = field(default=100.0, validator=V.number(gt=0, finite=True, what="a rate in Hz"))
    clock_rate: float = field(default=50.0, validator=V.number(gt=0, finite=True, what="a rate in Hz"))
    """How often /clock is published; in lockstep, how often the consumers are waited for."""
    clock_mode: ClockMode = field(default=ClockMode.REALTIME, converter=ClockMode)
    real_time_factor: float = field(default=1.0, validator=V.finite_positive)
    lockstep_consumers: list[str] = field(factory=list, converter=_consumers)
    """Components (with ``use_sim_time``) that must answer every /clock tick in lockstep."""
    compute_deadline: float | None = field(default=None, validator=attrs.validators.optional(V.finite_positive))
    """Lockstep only: charge the consumers' compute time. A command that arrives with a tick acts
    only after the CPU time the consumers' steps took for that tick (summed: the stack on one
    core), as on a robot whose computer takes that long; a tick whose charge exceeds this many
    seconds (the control period) counts as a deadline miss. None: commands act at once."""
    command_timeout: float = field(default=0.5, validator=V.finite_positive)
    """Simulated seconds without a new command after which the robot stops (a base's watchdog)."""
    command_array_step: float = field(default=0.1, validator=V.finite_positive)
    """Seconds each entry of a TwistArray command lasts (the controller's time step)."""

    joint_state_rate: float = field(default=30.0, validator=V.number(gt=0, finite=True, what="a rate in Hz"))
    """Arm joint states (the ``tabletop`` world)."""
    odom_rate: float = field(default=50.0, validator=V.number(gt=0, finite=True, what="a rate in Hz"))
    odom_noise: bool = False
    """True: wheel odometry with drift (OdometryConfig.noisy); False: ground truth."""
    odometry_mode: str | None = field(default=None, validator=_optional_choice("truth", "wheel", "wheel-imu"))
    """None: from ``odom_noise``. ``truth``, ``wheel`` (= odom_noise), or ``wheel-imu``: wheel
    odometry with an IMU's yaw (sensors/wheel_imu.py), what a real base's estimator gives."""
    drive: str | None = field(default=None, validator=_optional_choice("ideal", "skid-steer", "wheeled"))
    """The robot's drive model (actors/sim/dynamics); None = the robot preset's (``jackal-barn``:
    skid-steer, ``jackal-wheeled``: wheeled, the others: ideal). A drive's own command
    watchdog (0.25 s for the Jackal models) applies when shorter than ``command_timeout``."""
    scan_preset: str | None = field(default=None, validator=_optional_choice("jackal"))
    """``jackal``: the BARN Jackal's laser (sensors in jackal.py: 720 beams over +-2.356 rad,
    0.1-30 m, 50 Hz, 1 cm noise, 0.055 m ahead) instead of the ``scan_*`` fields."""
    scan_rate: float = field(default=10.0, validator=V.number(gt=0, finite=True, what="a rate in Hz"))
    scan_beams: int = field(default=360, validator=V.int_at_least(2))
    scan_fov_deg: float = field(default=360.0, validator=V.finite_positive)
    scan_range_max: float = field(default=10.0, validator=V.finite_positive)
    scan_noise_std: float = field(default=0.0, validator=V.finite_non_negative)
    camera_rate: float = field(default=10.0, validator=V.number(gt=0, finite=True, what="a rate in Hz"))
    camera_width: int = field(default=320, validator=V.int_at_least(8))
    camera_height: int = field(default=240, validator=V.int_at_least(8))
    camera_vfov_deg: float = field(default=60.0, validator=V.finite_positive)
    jpeg_quality: int = field(default=85, validator=V.int_at_least(1))
    slip: float = field(default=0.0, validator=V.finite_non_negative)
    actuation_noise: float = field(default=0.0, validator=V.finite_non_negative)
    seed: int = field(default=0, validator=V.int_at_least(0))
    loop_rate: float = field(default=10.0, validator=V.number(gt=0, finite=True, what="a rate in Hz"))
    """How often the component's own step runs (health reports); physics runs in its own thread."""

    def __attrs_post_init__(self) -> None:
        self.check_rates()

    def check_rates(self) -> None:
        if self.compute_deadline is not None and self.clock_mode is not ClockMode.LOCKSTEP:
            raise ValueError("SimulatorConfig.compute_deadline charges the consumers' compute time in lockstep; "
                             f"clock_mode is {self.clock_mode.value!r}")
        ticks = self.physics_rate / self.clock_rate
        if ticks < 1 - 1e-9 or abs(ticks - round(ticks)) > 1e-6:
            raise ValueError(f"SimulatorConfig: physics_rate ({self.physics_rate} Hz) must be a whole multiple of "
                             f"clock_rate ({self.clock_rate} Hz)")
        if self.scan_fov_deg > 360:
            raise ValueError(f"SimulatorConfig.scan_fov_deg must be in (0, 360], got {self.scan_fov_deg}")
        if self.jpeg_quality > 100:
            raise ValueError(f"SimulatorConfig.jpeg_quality must be in 1..100, got {self.jpeg_quality}")

    @property
    def ticks_per_clock(self) -> int:
        return int(round(self.physics_rate / self.clock_rate))
