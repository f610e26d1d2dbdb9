"""``FeetechArm``: an SO-100/SO-101 arm on a Feetech STS3215 bus as a robot plugin.

    arm = FeetechArm(component_name="arm", config=FeetechArmConfig(port="/dev/ttyUSB0"))
    arm.inputs(joint_command=Topic(name="joint_command", msg_type="JointState"))
    arm.outputs(joint_states=Topic(name="joint_states", msg_type="JointState"))

Keys: ``joint_command`` (in; JointState, or JointTrajectory whose last point is the goal: what
the VLA component and the Simulator's arm take) and ``joint_states`` (out; JointState). Both
default to the Simulator's arm topics, so ``recipes/vla_manipulation.py`` targets the real arm by
replacing the Simulator with this component. Either map the policy's joints to LeRobot's names
(``"elbow_flex.pos": "elbow_flex"``) or keep the recipe's map and name the servos as the simulated
arm does: ``FeetechArmConfig(joints={"Rotation": 1, "Pitch": 2, "Elbow": 3, "Wrist_Pitch": 4,
"Wrist_Roll": 5, "Jaw": 6})``.

Built on :class:`emos.actors.hardware.plugin.RobotPlugin` with a driver session (the bus is a
request/response protocol that :class:`.arm.ServoArm` runs). A joint command is taken in the step
its message arrives in; each poll (``loop_rate``, 100 Hz by default) is one bus cycle: a
SYNC_READ of every live joint's position/speed/load, a SYNC_WRITE of the goal positions, and a
JointState of the joints that answered, in radians (0 at encoder step 2048), named as LeRobot's
SO-100 follower names them unless ``config.joints`` says otherwise. Health, every step:

* HEALTHY: every servo answers;
* COMPONENT_FAILURE naming the servos that do not answer (the others keep working);
* SYSTEM_FAILURE naming the port while it is gone; the arm reconnects on a backoff ladder.

A missing or taken port fails activation with an error naming it. Actions: ``set_torque``
(on/off for every live servo), ``arm_status``.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from attrs import define, field

from emos.config import validators as V
from emos.core import clock

from ..plugin import Command, Feedback, PluginConfig, RobotPlugin, SessionTransport, plugin_action
from . import protocol as P
from .arm import SO100_JOINTS, Reading, ServoArm
from .protocol import Reg


def _check_joints(instance: Any, attribute: Any, value: Any) -> None:
    if not isinstance(value, Mapping) or not value:
        raise ValueError(f"FeetechArmConfig.joints: expected a non-empty {{joint name: servo id}} dict, got {value!r}")
    ids = list(value.values())
    if not all(isinstance(n, str) and n for n in value) or not all(
            isinstance(i, int) and not isinstance(i, bool) and 0 <= i <= P.MAX_ID for i in ids):
        raise ValueError(f"FeetechArmConfig.joints: names must be non-empty strings and ids integers 0..{P.MAX_ID}, got {value!r}")
    if len(set(ids)) != len(ids):
        raise ValueError(f"FeetechArmConfig.joints: two joints share a servo id: {value!r}")


def _check_port(instance: Any, attribute: Any, value: Any) -> None:
    if not isinstance(value, str) or not value:
        raise ValueError(f"FeetechArmConfig.port: expected a serial device path such as '/dev/ttyUSB0', got {value!r}")


@define(kw_only=True)
class FeetechArmConfig(PluginConfig):
    """The bus and the joints on it."""

    port: str = field(default="/dev/ttyUSB0", validator=_check_port)
    baudrate: int = field(default=1_000_000, validator=V.number(gt=0, integer=True))
    #: {joint name: servo id}; the SO-100 follower's by default
    joints: dict = field(factory=lambda: dict(SO100_JOINTS), validator=_check_joints)
    #: encoder step that is 0 rad
    zero_steps: int = field(default=P.STEPS_PER_TURN // 2, validator=V.number(ge=0, lt=P.STEPS_PER_TURN, integer=True))
    #: seconds to wait for answers beyond their wire time
    response_timeout: float = field(default=0.02, validator=V.number(gt=0, finite=True))
    #: Return Delay Time written to each servo at start (2 us units; LeRobot writes 0); None leaves it
    return_delay_time: int | None = field(default=0, validator=V.number(ge=0, le=254, integer=True, allow_none=True))
    torque_on_start: bool = field(default=True)
    #: seconds between pings of a servo that stopped answering
    reping_period: float = field(default=1.0, validator=V.number(gt=0, finite=True))


class FeetechArm(RobotPlugin):
    """An arm of Feetech STS3215 servos (module docstring)."""

    plugin_name = "feetech"
    description = "SO-100/SO-101 arm on a Feetech STS3215 servo bus (STS/SCS protocol)"
    feedback: ClassVar[Mapping[str, Feedback]] = {"joint_states": Feedback(msg_type="JointState", topic="joint_states", help="position, velocity, load")}
    commands: ClassVar[Mapping[str, Command]] = {"joint_command": Command(msg_types=("JointState", "JointTrajectory"), topic="joint_command",
                                         help="goal positions (a trajectory's last point)")}

    def __init__(self, component_name: str = "arm", config: FeetechArmConfig | None = None, **kwargs: Any) -> None:
        super().__init__(component_name, config or FeetechArmConfig(), **kwargs)
        self.config: FeetechArmConfig
        self.arm: ServoArm | None = None
        self._targets: dict[str, float] | None = None
        self.bad_commands = 0

    @classmethod
    def config_class(cls) -> type[FeetechArmConfig]:
        return FeetechArmConfig

    # -- transport -------------------------------------------------------------------------------
    def make_transports(self) -> Mapping[str, SessionTransport]:
        cfg = self.config
        arm = ServoArm(cfg.port, cfg.joints, baudrate=cfg.baudrate, timeout=cfg.response_timeout, zero_steps=cfg.zero_steps,
                       return_delay_time=cfg.return_delay_time, torque_on_start=cfg.torque_on_start, reping_period=cfg.reping_period)

        def start() -> None:
            arm.start()  # FeetechPortError / FeetechNoAnswer name the port and servos: activation fails with them
            self.arm, self._targets = arm, None
            self.get_logger().info("[%s] Feetech arm on %s: %s%s", self.component_name, cfg.port,
                                   ", ".join(f"{n}={i}" for n, i in cfg.joints.items()),
                                   f"; not answering: {'; '.join(arm.lost.values())}" if arm.lost else "")

        def stop() -> None:
            self.arm = None
            arm.stop()

        # The arm reconnects inside a bus cycle (its own ladder): a cycle without goals is a rung.
        return {"bus": SessionTransport("Feetech bus", cfg.port, start=start, stop=stop,
                                        error=lambda: arm.disconnected, retry=lambda: arm.cycle(None))}

    # -- commands and the bus cycle ----------------------------------------------------------------
    def on_command(self, key: str, msg: Any) -> None:
        arm = self.arm
        if arm is None:
            return
        try:
            names, positions = joint_targets(msg)
        except (TypeError, ValueError) as exc:
            self.bad_commands += 1
            self._rlog.warning("bad command", "[%s] joint command refused: %s", self.component_name, exc)
            return
        targets = dict(zip(names, positions, strict=True))
        refused = [n for n, v in targets.items() if n not in arm.joints or not math.isfinite(v)]
        if refused:
            self.bad_commands += 1
            self._rlog.warning(("refused", tuple(refused)), "[%s] joint command: unknown joints or non-finite positions %s "
                               "(this arm has %s)", self.component_name, refused, list(arm.joints))
        self._targets = {**(self._targets or {}), **{n: v for n, v in targets.items() if n not in refused}}

    def on_poll(self) -> None:
        arm = self.arm
        if arm is None:
            return
        targets, self._targets = self._targets, None
        reading = arm.cycle(targets)
        if reading is None:
            return  # the port went away: the next poll reports it (SYSTEM_FAILURE naming it) and reconnects
        if reading.names:
            self._publish(reading)
        self.device_problem = "servos not answering: " + "; ".join(arm.lost.values()) if arm.lost else ""

    def _publish(self, reading: Reading) -> None:
        from emos.msgs import JointState
        from emos.msgs.std import Header

        self.emit("joint_states", JointState(header=Header(stamp=clock.stamp()), name=reading.names,
                                       position=np.asarray(reading.position, dtype=float),
                                       velocity=np.asarray(reading.velocity, dtype=float),
                                       effort=np.asarray(reading.effort, dtype=float)))

    # -- plugin actions (events, `emos component call NAME execute_method method=...`) ------------
    @plugin_action("torque on (hold) or off (limp) for every live servo")
    def set_torque(self, on: bool) -> list[str]:
        arm = self.arm
        if arm is None:
            return []
        done = []
        for name, servo_id in arm.joints.items():
            if servo_id not in arm.lost:
                arm.bus.write(servo_id, Reg.TORQUE_ENABLE, 1 if on else 0)
                done.append(name)
        return done

    @plugin_action("port, servos not answering, reconnects, dropped bytes, refused commands")
    def arm_status(self) -> dict:
        arm = self.arm
        if arm is None:
            return {"running": False}
        return {"running": True, "port": arm.port, "lost": dict(arm.lost), "disconnected": arm.disconnected,
                "reconnects": arm.reconnects, "dropped_bytes": arm.bus.dropped_bytes, "bad_commands": self.bad_commands}


def joint_targets(msg: Any) -> tuple[list[str], list[float]]:
    """(joint names, positions) of a JointState, or of a JointTrajectory's last point (its goal).
    The same reading of a joint command as the Simulator's (actors/sim/component/commands.py)."""
    from emos.msgs import JointState, JointTrajectory

    if isinstance(msg, JointState):
        names, positions = list(msg.name), [float(v) for v in msg.position]
    elif isinstance(msg, JointTrajectory):
        if not msg.points:
            raise ValueError("JointTrajectory has no points")
        names, positions = list(msg.joint_names), [float(v) for v in msg.points[-1].positions]
    else:
        raise TypeError(f"joint_command must be JointState or JointTrajectory, got {type(msg).__name__}")
    if len(names) != len(positions):
        raise ValueError(f"joint command names {names} and positions {positions} differ in length")
    return names, positions
