"""The emulated Feetech STS3215 bus driving the pybullet table-top arm: an SO-101 without hardware.

:class:`SimulatedArm` builds the Simulator's table-top world (:func:`emos.actors.sim.arm.tabletop_world`)
and serves the same byte-faithful :class:`~.emulator.BusEmulator` on a pseudo-terminal, with one
:class:`PybulletServo` per joint in place of the in-memory kinematic motor (servo ids 1..6 are
``Rotation, Pitch, Elbow, Wrist_Pitch, Wrist_Roll, Jaw``: :data:`SERVO_JOINTS`). The bus protocol,
its timing and its faults (silent servos, unplug/replug, line noise) are the emulator's, untouched.

Each servo is an STS3215 driving its pybullet joint:

* its profile generator moves a setpoint toward the goal position (clamped to the servo's
  min/max position limit registers, as the kinematic model does) at the goal speed register,
  0 meaning and capped at the STS3215's no-load 3072 steps/s (``ServoModel.speed_limit``), with
  the acceleration register's ramp (units of 100 steps/s^2, Feetech's STS memory table; 0 = no
  ramp, as the kinematic model takes it); pybullet's position control tracks that setpoint with
  its velocity as feedforward, and the joint's velocity is capped at the no-load speed
  (``maxJointVelocity``) so nothing, not even gravity, moves it faster than the servo can;
* the present position, speed and load registers are pybullet's joint state at the last tick
  (the bus is answered from it, never waiting for a physics step, as a servo samples its encoder):
  steps through :class:`~.arm.ServoArm`'s own conversion (0 rad at step 2048,
  :data:`~.arm.RAD_PER_STEP`), speed in steps/s (sign-magnitude), load in 0.1 % of the joint's
  effort with the sign in bit 10. An STS reports its PWM duty as load; a servo held away from its
  setpoint (a joint pushed against its limit, a blocked gripper) drives full duty, so the load is
  the larger of pybullet's motor torque and the tracking error over :data:`FULL_LOAD_ERROR_RAD`;
* torque off: the joint is left to a gear-train friction (:data:`TORQUE_OFF_FRICTION` of its
  effort) and gravity; torque on again holds where the joint is.

Time is the world's: :meth:`SimulatedArm.start` steps it in real time (10 ms ticks) from a thread;
``start(stepping=False)`` leaves the stepping to the caller's :meth:`SimulatedArm.step` (tests:
the trajectory is then sampled tick by tick, whatever the machine's load).
"""
from __future__ import annotations

import math
import threading
import time
from typing import Any

import numpy as np

from . import protocol as P
from .arm import RAD_PER_STEP, ServoArm
from .emulator import BusEmulator, ServoModel, serve_until_stopped
from .protocol import Reg

__all__ = ["FULL_LOAD_ERROR_RAD", "SERVO_JOINTS", "PybulletServo", "SimulatedArm", "main"]

#: The arm's joints by servo id, as ``FeetechArmConfig(joints=...)`` names them for the simulated arm.
SERVO_JOINTS: dict[str, int] = {"Rotation": 1, "Pitch": 2, "Elbow": 3, "Wrist_Pitch": 4, "Wrist_Roll": 5, "Jaw": 6}
ACC_UNIT_STEPS_PER_S2 = 100.0  # acceleration register unit (Feetech STS memory table: 100 step/s^2)
FULL_LOAD_ERROR_RAD = 0.1  # a servo held this far from its setpoint drives full PWM (load 100 %)
TORQUE_OFF_FRICTION = 0.1  # fraction of the joint's effort the unpowered gear train resists with
MAX_SPEED_RAD_S = P.MAX_SPEED_STEPS_PER_S * RAD_PER_STEP
MOVING_SPEED_STEPS_S = 20.0  # below this (and at the goal) the MOVING register reads 0
POSITION_GAIN, VELOCITY_GAIN = 0.5, 1.0  # pybullet's position control tracking the servo's setpoint


class Calibration(ServoArm):
    """The driver's step <-> radian conversion: :class:`~.arm.ServoArm`'s own ``to_rad`` and
    ``to_steps`` (one home), without its bus: only ``zero_steps`` is set, nothing is opened."""

    def __init__(self, zero_steps: int = P.STEPS_PER_TURN // 2) -> None:  # no super().__init__(): that builds a bus
        self.zero_steps = zero_steps


class PybulletServo(ServoModel):
    """One STS3215 whose motor is a pybullet joint of ``sim``'s arm (module docstring)."""

    def __init__(self, servo_id: int, sim: SimulatedArm, joint: str) -> None:
        self.sim, self.joint = sim, joint
        self.index = sim.arm.joint_index[joint]
        self.effort = float(sim.world.client.getJointInfo(sim.arm.body_id, self.index)[10])
        q = sim.states[self.index][0]
        start = sim.cal.to_steps(q)
        super().__init__(servo_id, position=start, clock=sim.now)
        self.setpoint = float(start)  # steps (fractional): where the profile generator is
        self.velocity = 0.0  # steps/s of the setpoint
        self._on = False

    # -- the bus side (the emulator's thread) ------------------------------------------------------
    def update(self, now: float | None = None) -> None:
        """The present registers from pybullet's joint state now."""
        with self.sim.lock:
            q, qd, tau = self.sim.states[self.index]
            present = self.sim.cal.to_steps(q)
            self.position = float(present)
            speed = int(round(qd / RAD_PER_STEP))
            speed = max(-0x7FFF, min(0x7FFF, speed))
            load = abs(tau) / self.effort if self.effort > 0 else 0.0
            sign = -1.0 if tau < 0 else 1.0
            if self._on:
                error = self.sim.cal.to_rad(self.setpoint) - q  # type: ignore[arg-type]  # linear: fractional steps work
                if abs(error) / FULL_LOAD_ERROR_RAD > load:
                    load, sign = abs(error) / FULL_LOAD_ERROR_RAD, (-1.0 if error < 0 else 1.0)
            permille = int(round(min(load, 1.0) * 1000))
            self._put(Reg.PRESENT_POSITION, present)
            self._put(Reg.PRESENT_SPEED, speed)
            self._put(Reg.PRESENT_LOAD, P.encode_sign_magnitude(int(sign) * permille, 10))
            goal = self._goal()
            moving = self._on and (abs(goal - self.setpoint) >= 0.5 or abs(speed) > MOVING_SPEED_STEPS_S)
            self.table[Reg.MOVING.address] = 1 if moving else 0

    def read(self, address: int, length: int) -> bytes | None:
        with self.sim.lock:  # the stepper never sees half a read
            return super().read(address, length)

    def write(self, address: int, data: bytes) -> bool:
        with self.sim.lock:  # nor half of a two-byte goal
            return super().write(address, data)

    # -- the motor side (the stepper, under sim.lock) ---------------------------------------------
    def _goal(self) -> int:
        lo, hi = self.get(Reg.MIN_POSITION_LIMIT), self.get(Reg.MAX_POSITION_LIMIT)
        return min(max(self.get(Reg.GOAL_POSITION), lo), hi)

    def plan(self, q: float, dt: float) -> tuple[float, float] | None:
        """Advance the profile by ``dt``: (setpoint rad, its rad/s), or None with torque off."""
        if not self.table[Reg.TORQUE_ENABLE.address]:
            self._on = False
            return None
        if not self._on:  # torque just came on: hold where the joint is
            self._on, self.setpoint, self.velocity = True, float(self.sim.cal.to_steps(q)), 0.0
        vmax = self.speed_limit
        acc = self.get(Reg.ACCELERATION)
        amax = acc * ACC_UNIT_STEPS_PER_S2 if acc else math.inf
        error = self._goal() - self.setpoint
        # the fastest speed from which the ramp still stops at the goal, and no overshoot this tick
        want = min(vmax, math.sqrt(2.0 * amax * abs(error)), abs(error) / dt)
        want = math.copysign(want, error)
        step = amax * dt
        self.velocity += min(max(want - self.velocity, -step), step)
        self.setpoint += self.velocity * dt
        return self.sim.cal.to_rad(self.setpoint), self.velocity * RAD_PER_STEP  # type: ignore[arg-type]


class SimulatedArm:
    """The table-top pybullet world with its arm on an emulated Feetech bus at :attr:`path`."""

    def __init__(self, *, link_dir: str | None = None, dt: float = 0.01, baudrate: int = 1_000_000,
                 return_delay: int | None = None, world: Any = None) -> None:
        from emos.actors.sim.arm import tabletop_world
        from emos.actors.sim.clock import ClockMode, SimClock

        # Lockstep: the world advances only when this class steps it (its thread or the caller).
        self.world = world if world is not None else tabletop_world(clock=SimClock(dt=dt, mode=ClockMode.LOCKSTEP))
        self.arm = self.world.arm
        self.dt = float(self.world.clock.dt)
        self.cal = Calibration()
        # The bus thread answers from the joint states of the last tick (``states``, under ``lock``,
        # held only briefly): a read never waits for a physics step, as a servo samples its encoder.
        # Only ``_pb_lock``'s holder talks to the one pybullet client.
        self.lock = threading.RLock()
        self._pb_lock = threading.Lock()
        self.states: dict[int, tuple[float, float, float]] = {}  # joint index -> (rad, rad/s, N m)
        missing = [n for n in SERVO_JOINTS if n not in self.arm.joint_index]
        if missing:
            raise ValueError(f"SimulatedArm: the arm has no joint(s) {missing}; its joints are {self.arm.names}")
        self._sample()
        joint_of = {i: n for n, i in SERVO_JOINTS.items()}
        client = self.world.client
        for name in SERVO_JOINTS:  # the servo's no-load speed bounds the joint, whatever pushes it
            client.changeDynamics(self.arm.body_id, self.arm.joint_index[name], maxJointVelocity=MAX_SPEED_RAD_S)
        self.bus = BusEmulator(list(SERVO_JOINTS.values()), baudrate=baudrate, return_delay=return_delay,
                               link_dir=link_dir, servo_factory=lambda i: PybulletServo(i, self, joint_of[i]))
        self.servos: dict[int, PybulletServo] = self.bus.servos  # type: ignore[assignment]
        self.ticks = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def path(self) -> str:
        return self.bus.path

    def now(self) -> float:
        """World time (s)."""
        return float(self.world.clock.now())

    def start(self, stepping: bool = True) -> SimulatedArm:
        self.bus.start()
        if stepping:
            self._thread = threading.Thread(target=self._run, name="feetech-simarm", daemon=True)
            self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self.bus.close()
        self.world.close()

    def __enter__(self) -> SimulatedArm:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _run(self) -> None:
        next_tick = time.monotonic()
        while not self._stop.wait(max(0.0, next_tick - time.monotonic())):
            self.step()
            next_tick += self.dt
            if time.monotonic() - next_tick > 0.5:  # a stalled machine: do not replay seconds at once
                next_tick = time.monotonic()

    def step(self) -> None:
        """One world tick: every servo's profile, its joint's motor, pybullet's physics."""
        from emos.actors.sim import _deps

        pb = _deps.pybullet()
        arm, client = self.arm, self.world.client
        with self.lock:  # the registers and the profiles: the bus waits only for this
            plans = [(servo, servo.plan(self.states[servo.index][0], self.dt)) for servo in self.servos.values()]
        with self._pb_lock:
            for servo, target in plans:
                if target is None:  # limp: only the gear train's friction
                    client.setJointMotorControl2(arm.body_id, servo.index, pb.VELOCITY_CONTROL, targetVelocity=0.0,
                                                 force=TORQUE_OFF_FRICTION * servo.effort)
                    arm.targets[servo.joint] = self.states[servo.index][0]
                    continue
                client.setJointMotorControl2(arm.body_id, servo.index, pb.POSITION_CONTROL, targetPosition=target[0],
                                             targetVelocity=target[1], force=servo.effort,
                                             positionGain=POSITION_GAIN, velocityGain=VELOCITY_GAIN)
                arm.targets[servo.joint] = target[0]  # the grasp logic reads the jaw's target
            self.world.step()
        self._sample()
        self.ticks += 1

    def _sample(self) -> None:
        """Take this tick's joint states for the bus to answer from."""
        index = [self.arm.joint_index[n] for n in SERVO_JOINTS]
        with self._pb_lock:
            got = self.world.client.getJointStates(self.arm.body_id, index)
        with self.lock:
            self.states = {j: (float(st[0]), float(st[1]), float(st[3])) for j, st in zip(index, got)}

    def joint_states(self) -> tuple[float, dict[str, tuple[float, float]]]:
        """(world time, {joint: (rad, rad/s)}) straight from pybullet."""
        with self._pb_lock:
            states = self.world.client.getJointStates(self.arm.body_id, [self.arm.joint_index[n] for n in SERVO_JOINTS])
            return self.now(), {n: (float(s[0]), float(s[1])) for n, s in zip(SERVO_JOINTS, states)}

    def positions(self) -> np.ndarray:
        """The joints' radians in servo-id order."""
        _, states = self.joint_states()
        return np.array([states[n][0] for n in SERVO_JOINTS])


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(prog="python -m emos.actors.hardware.feetech.simarm",
                                     description="The pybullet table-top arm on an emulated Feetech STS3215 bus (a pty).")
    parser.add_argument("--return-delay", type=int, default=None,
                        help="Return Delay Time register (2 us units; default the factory 250)")
    args = parser.parse_args(argv)
    return serve_until_stopped(SimulatedArm(return_delay=args.return_delay),
                               f"Feetech bus emulator on the pybullet arm: servos {SERVO_JOINTS}")


if __name__ == "__main__":
    raise SystemExit(main())
