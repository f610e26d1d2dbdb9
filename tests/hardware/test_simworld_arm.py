"""The Feetech STS3215 bus emulator backed by the pybullet table-top arm, driven through our real
Feetech driver on the pty: goals written over the bus move the pybullet joints at the servo's
speed (and acceleration) limits, and the present registers read back are pybullet's state."""
from __future__ import annotations

import time

import numpy as np
import pytest

from emos.actors.hardware.feetech.arm import RAD_PER_STEP, ServoArm
from emos.actors.hardware.feetech.protocol import MAX_SPEED_STEPS_PER_S, Reg
from emos.actors.hardware.feetech.simarm import ACC_UNIT_STEPS_PER_S2, SERVO_JOINTS, SimulatedArm

pytestmark = pytest.mark.sim

NAMES = list(SERVO_JOINTS)
IDS = list(SERVO_JOINTS.values())
ANSWER_S = 0.5  # the driver's answer timeout in these tests: late answers on a loaded machine are not silence
GOALS = {"Rotation": 1.0, "Pitch": -0.5, "Elbow": 0.6, "Wrist_Pitch": 1.0, "Wrist_Roll": -1.0, "Jaw": 1.0}


@pytest.fixture
def stepped(tmp_path):
    """The arm whose world the test steps itself (the trajectory is sampled every tick)."""
    sim = SimulatedArm(link_dir=str(tmp_path)).start(stepping=False)
    # The emulator answers from a thread of this process: at the driver's 20 ms default a loaded
    # machine made servo 2 miss its bring-up PING, and a lost servo is never moved. A generous
    # answer timeout only bounds a hang (ANSWER_S).
    arm = ServoArm(sim.path, SERVO_JOINTS, timeout=ANSWER_S)
    arm.start()
    yield sim, arm
    arm.stop()
    sim.close()


def _send(arm: ServoArm, goals: dict) -> None:
    """One bus cycle with the goals (SYNC_READ + SYNC_WRITE), then one more cycle: its SYNC_READ's
    answer proves the emulator has handled the SYNC_WRITE (the bus is served in order)."""
    assert arm.cycle(goals) is not None
    assert arm.cycle() is not None


def _trajectory(sim: SimulatedArm, ticks: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times, positions, pybullet velocities) after each of ``ticks`` world steps."""
    times, pos, vel = [], [], []
    for _ in range(ticks):
        sim.step()
        t, states = sim.joint_states()
        times.append(t)
        pos.append([states[n][0] for n in NAMES])
        vel.append([states[n][1] for n in NAMES])
    return np.array(times), np.array(pos), np.array(vel)


def _max_speed(times: np.ndarray, pos: np.ndarray) -> np.ndarray:
    return np.max(np.abs(np.diff(pos, axis=0)) / np.diff(times)[:, None], axis=0)


def test_sync_write_moves_the_pybullet_joints_no_faster_than_the_servo(stepped):
    sim, arm = stepped
    limit = MAX_SPEED_STEPS_PER_S * RAD_PER_STEP  # 4.71 rad/s: goal speed 0 = the servo's maximum
    _send(arm, GOALS)
    times, pos, vel = _trajectory(sim, 150)  # 1.5 s of world time
    speeds = _max_speed(times, pos)
    assert np.all(speeds <= limit * 1.01), f"joint speeds {speeds} exceed the STS3215's {limit} rad/s"
    assert np.all(np.abs(vel) <= limit * 1.01)
    assert speeds[NAMES.index("Rotation")] >= 0.9 * limit  # it really runs at the servo's speed
    np.testing.assert_allclose(pos[-1], [GOALS[n] for n in NAMES], atol=0.02)


def test_goal_speed_and_acceleration_registers_limit_the_motion(stepped):
    sim, arm = stepped
    speed, acc = 1000, 20  # steps/s, and 20 x 100 steps/s^2
    arm.bus.sync_write(Reg.GOAL_SPEED, {i: speed for i in IDS})
    arm.bus.sync_write(Reg.ACCELERATION, {i: acc for i in IDS})
    start = sim.positions()
    _send(arm, GOALS)
    times, pos, _ = _trajectory(sim, 300)
    speeds = _max_speed(times, pos)
    limit = speed * RAD_PER_STEP
    assert np.all(speeds <= limit * 1.03), f"joint speeds {speeds} exceed the goal speed's {limit} rad/s"
    rot = NAMES.index("Rotation")
    assert speeds[rot] >= 0.9 * limit
    # the ramp: 0.2 s after the start the joint covered about a t^2 / 2, not the speed's v t
    t0 = times[0] - sim.dt
    early = np.searchsorted(times, t0 + 0.2)
    ramp = 0.5 * acc * ACC_UNIT_STEPS_PER_S2 * RAD_PER_STEP * 0.2 ** 2
    assert abs(pos[early, rot] - start[rot]) <= 1.5 * ramp + 0.01 < limit * 0.2
    np.testing.assert_allclose(pos[-1], [GOALS[n] for n in NAMES], atol=0.02)


def test_sync_read_returns_what_pybullet_says(stepped):
    sim, arm = stepped
    _send(arm, GOALS)
    for ticks in (5, 200):  # mid-motion, then at rest
        _trajectory(sim, ticks)
        _, states = sim.joint_states()
        reading = arm.cycle()
        assert reading is not None and reading.names == NAMES
        for name, got_pos, got_vel in zip(reading.names, reading.position, reading.velocity):
            q, qd = states[name]
            assert abs(got_pos - q) <= RAD_PER_STEP / 2 + 1e-9, (name, got_pos, q)
            assert abs(got_vel - qd) <= RAD_PER_STEP / 2 + 1e-9, (name, got_vel, qd)
        present = arm.bus.sync_read(Reg.PRESENT_POSITION, IDS)
        assert present == {i: sim.cal.to_steps(states[n][0]) for n, i in SERVO_JOINTS.items()}


def test_a_joint_pushed_against_its_limit_reports_it(tmp_path):
    """Real-time stepping, the driver cycling as the FeetechArm component does."""
    with SimulatedArm(link_dir=str(tmp_path)) as sim:
        lo, hi = sim.arm.limits["Rotation"]
        # The physics shares this process (and a loaded machine): a generous answer timeout, so a
        # late answer is not taken for a silent servo (it only bounds a hang).
        arm = ServoArm(sim.path, SERVO_JOINTS, timeout=ANSWER_S)
        arm.start()
        try:
            goal = hi + 0.6  # beyond the joint's mechanical stop
            deadline, ticks = time.monotonic() + 60.0, sim.ticks  # bounds a hang only
            while True:
                assert time.monotonic() < deadline, "the joint never settled at its stop"
                reading = arm.cycle({"Rotation": goal})
                assert reading is not None
                got = {n: (p, v, e) for n, p, v, e in zip(reading.names, reading.position, reading.velocity, reading.effort)}
                if "Rotation" in got and "Wrist_Roll" in got:
                    pos, vel, load = got["Rotation"]
                    if abs(pos - hi) < 0.01 and abs(vel) < 0.05 and sim.ticks - ticks > 100:  # > 1 s of world time
                        break
                time.sleep(0.01)
            _, states = sim.joint_states()
            assert abs(states["Rotation"][0] - hi) < 0.01  # pybullet holds it at the stop
            assert load >= 99.0  # full load, pushing toward +
            assert abs(got["Wrist_Roll"][2]) < 50.0  # a free joint is not loaded
        finally:
            arm.stop()
