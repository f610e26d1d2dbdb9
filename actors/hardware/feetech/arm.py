"""``ServoArm``: named joints on a Feetech bus, one read + write cycle at a time, surviving faults.

    arm = ServoArm("/dev/ttyUSB0", SO100_JOINTS)
    arm.start()                               # opens, pings every servo, enables torque
    reading = arm.cycle({"elbow_flex": 0.3})  # SYNC_READ of all joints + SYNC_WRITE of goals

This is the device layer the ``FeetechArm`` component (and later a robot plugin) wraps; it has no
topics. Positions are radians from the 4096-step encoder, 0 rad at ``zero_steps`` (2048, the
middle of the range). Faults, each named:

* the port is missing or taken: :meth:`start` raises :class:`~.driver.FeetechPortError`;
* a servo does not answer (at start or mid-run): it is listed in :attr:`ServoArm.lost` with the
  reason, left out of the sync reads (so its silence costs the others no timeout) and pinged
  again every ``reping_period`` s; the other joints keep working;
* the port dies (unplugged): :meth:`cycle` returns ``None`` with :attr:`disconnected` set to the
  reason, and each later call tries to reopen on a backoff ladder (``emos.core.retry.Backoff``);
  when the port is back the servos are pinged, torque enabled and goals reset to where they are.
"""
from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from typing import NamedTuple

from emos.core.retry import Backoff
from emos.ratelimit import RateLimitedLog

from . import protocol as P
from .driver import DEFAULT_BAUDRATE, FeetechBus, FeetechDisconnected, FeetechNoAnswer
from .protocol import Reg

log = logging.getLogger("emos.hardware.feetech")

#: The SO-100/SO-101 follower arm's joints and servo ids, as LeRobot's ``SO100Follower`` names them.
SO100_JOINTS: dict[str, int] = {"shoulder_pan": 1, "shoulder_lift": 2, "elbow_flex": 3,
                                "wrist_flex": 4, "wrist_roll": 5, "gripper": 6}
RAD_PER_STEP = 2.0 * math.pi / P.STEPS_PER_TURN
#: One SYNC_READ covers present position (56-57), speed (58-59) and load (60-61).
STATE_ADDRESS, STATE_LENGTH = Reg.PRESENT_POSITION.address, 6


class Reading(NamedTuple):
    """The joints that answered this cycle, in configured order: radians, rad/s, load (% of max, signed)."""

    names: list[str]
    position: list[float]
    velocity: list[float]
    effort: list[float]


class ServoArm:
    """Joints by name on one Feetech bus (module docstring)."""

    def __init__(self, port: str, joints: Mapping[str, int] | None = None, *, baudrate: int = DEFAULT_BAUDRATE,
                 timeout: float = 0.02, zero_steps: int = P.STEPS_PER_TURN // 2, return_delay_time: int | None = 0,
                 torque_on_start: bool = True, reping_period: float = 1.0,
                 reconnect: Backoff | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        joints = dict(SO100_JOINTS if joints is None else joints)
        if not joints:
            raise ValueError("ServoArm: give at least one joint {name: servo id}")
        ids = list(joints.values())
        if len(set(ids)) != len(ids) or not all(isinstance(i, int) and 0 <= i <= P.MAX_ID for i in ids):
            raise ValueError(f"ServoArm: joints must map names to distinct servo ids 0..{P.MAX_ID}, got {joints}")
        self.joints = joints
        self.names_by_id = {i: n for n, i in joints.items()}
        self.bus = FeetechBus(port, baudrate, timeout)
        self.zero_steps = zero_steps
        self.return_delay_time = return_delay_time
        self.torque_on_start = torque_on_start
        self.reping_period = reping_period
        self.reconnect = reconnect or Backoff(base=0.1, factor=2.0, cap=2.0, timeout=math.inf)
        self.clock = clock
        self.goals: dict[int, int] = {}  # goal steps per live servo
        self.lost: dict[int, str] = {}  # servo id -> why it is left out
        self.disconnected: str | None = None
        self.reconnects = 0
        self._failures = 0
        self._retry_at = 0.0
        self._reping_at = 0.0
        self._rlog = RateLimitedLog(log, 5.0)

    @property
    def port(self) -> str:
        return self.bus.port

    def describe(self, servo_id: int) -> str:
        return f"servo {servo_id} ({self.names_by_id.get(servo_id, '?')}) on {self.port}"

    # -- conversions -------------------------------------------------------------------------------
    def to_rad(self, steps: int) -> float:
        return (steps - self.zero_steps) * RAD_PER_STEP

    def to_steps(self, rad: float) -> int:
        return min(max(int(round(rad / RAD_PER_STEP)) + self.zero_steps, 0), P.STEPS_PER_TURN - 1)

    # -- start, stop -------------------------------------------------------------------------------
    def start(self) -> None:
        """Open the port and bring up every servo that answers; raise if none does."""
        self.bus.open()
        try:
            self._bring_up(list(self.joints.values()))
        except FeetechDisconnected:
            self.bus.close()
            raise
        if len(self.lost) == len(self.joints):
            self.bus.close()
            raise FeetechNoAnswer(f"Feetech bus {self.port!r}: no servo answered: " + "; ".join(self.lost.values()), self.lost)
        self._reping_at = self.clock() + self.reping_period

    def stop(self) -> None:
        self.bus.close()

    def _bring_up(self, ids: list[int]) -> None:
        """Ping, configure and hold in place each of ``ids``; those that do not answer go to ``lost``."""
        for servo_id in ids:
            try:
                model = self.bus.ping(servo_id)
                if model != P.STS3215_MODEL:
                    self._rlog.warning(("model", servo_id), "[feetech] %s reports model %d, not an STS3215 (%d)",
                                       self.describe(servo_id), model, P.STS3215_MODEL)
                if self.return_delay_time is not None:
                    self.bus.write(servo_id, Reg.RETURN_DELAY_TIME, self.return_delay_time)
                if self.torque_on_start:
                    self.bus.write(servo_id, Reg.TORQUE_ENABLE, 1)
                # hold where it is: the first write of goals must not move the arm
                self.goals[servo_id] = self.bus.read(servo_id, Reg.PRESENT_POSITION)
                if self.lost.pop(servo_id, None) is not None:
                    log.warning("[feetech] %s answers again", self.describe(servo_id))
            except FeetechNoAnswer:
                self._lose(servo_id, "does not answer PING")

    def _lose(self, servo_id: int, why: str) -> None:
        if servo_id not in self.lost:
            log.error("[feetech] %s %s; the other joints keep working", self.describe(servo_id), why)
        self.lost[servo_id] = f"{self.describe(servo_id)} {why}"
        self.goals.pop(servo_id, None)

    # -- the cycle ---------------------------------------------------------------------------------
    def set_goals(self, targets: Mapping[str, float]) -> list[str]:
        """Set goal positions (radians) by joint name; returns the names it does not know or could not use."""
        refused = []
        for name, rad in targets.items():
            servo_id = self.joints.get(name)
            if servo_id is None or not math.isfinite(rad):
                refused.append(name)
            elif servo_id in self.goals:
                self.goals[servo_id] = self.to_steps(rad)
        return refused

    def cycle(self, targets: Mapping[str, float] | None = None) -> Reading | None:
        """One SYNC_READ of the live joints' state and one SYNC_WRITE of their goals.

        ``targets``: new goal positions by joint name (radians). Returns the joints that answered,
        or ``None`` while the port is down (``disconnected`` says why; reconnects are tried here)."""
        if not self.bus.is_open and not self._try_reconnect():
            return None
        try:
            if targets:
                self.set_goals(targets)
            live = [i for i in self.joints.values() if i not in self.lost]
            got = self.bus.transact(P.sync_read(STATE_ADDRESS, STATE_LENGTH, live), live, 6 + STATE_LENGTH) if live else {}
            for servo_id in live:
                if servo_id not in got or len(got[servo_id].params) != STATE_LENGTH:
                    self._lose(servo_id, "did not answer SYNC_READ")
            if self.goals:
                self.bus.sync_write(Reg.GOAL_POSITION, self.goals)
            if self.lost and self.clock() >= self._reping_at:
                self._reping_at = self.clock() + self.reping_period
                self._bring_up(list(self.lost))
        except FeetechDisconnected as exc:
            self._drop(str(exc))
            return None
        reading = Reading([], [], [], [])
        for name, servo_id in self.joints.items():
            pkt = got.get(servo_id)
            if pkt is None or servo_id in self.lost:
                continue
            data = pkt.params
            reading.names.append(name)
            reading.position.append(self.to_rad(P.decode_value(Reg.PRESENT_POSITION, data[0:2])))
            reading.velocity.append(P.decode_value(Reg.PRESENT_SPEED, data[2:4]) * RAD_PER_STEP)
            reading.effort.append(P.decode_sign_magnitude(int.from_bytes(data[4:6], "little"), 10) / 10.0)
        return reading

    # -- the port going away and coming back -------------------------------------------------------
    def _drop(self, why: str) -> None:
        log.error("[feetech] %s; reconnecting", why)
        self.bus.close()
        self.disconnected = why
        self._failures = 0
        self._retry_at = self.clock() + self.reconnect.delay(1)

    def _try_reconnect(self) -> bool:
        now = self.clock()
        if now < self._retry_at:
            return False
        self._failures += 1
        try:
            self.bus.open()
            self.goals.clear()
            self.lost.clear()
            self._bring_up(list(self.joints.values()))
        except Exception as exc:  # missing port, dead port, nobody answering: try again later
            self.bus.close()
            self._retry_at = now + self.reconnect.delay(self._failures + 1)
            self.disconnected = f"Feetech bus {self.port!r}: reconnect attempt {self._failures} failed: {exc}"
            self._rlog.warning(("reconnect", self.port), "[feetech] %s", self.disconnected)
            return False
        log.warning("[feetech] serial port %r is back after %d attempt(s)", self.port, self._failures)
        self.disconnected = None
        self.reconnects += 1
        self._reping_at = now + self.reping_period
        return True
