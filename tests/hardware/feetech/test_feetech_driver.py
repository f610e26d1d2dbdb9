"""The Feetech driver (FeetechBus, ServoArm) and the FeetechArm component against the emulated bus."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from emos.actors.hardware.feetech import protocol as P
from emos.actors.hardware.feetech.arm import RAD_PER_STEP, SO100_JOINTS, ServoArm
from emos.actors.hardware.feetech.bench import servo_cycle_hz
from emos.actors.hardware.feetech.component import FeetechArm, FeetechArmConfig
from emos.actors.hardware.feetech.driver import FeetechBus, FeetechNoAnswer, FeetechPortError
from emos.actors.hardware.feetech.protocol import Reg
from emos.core.health import HealthLevel
from emos.io.topic import Topic
from emos.msgs import JointState, JointTrajectory, JointTrajectoryPoint
from emos.testing import ComponentHarness

pytestmark = pytest.mark.process  # an emulator thread on a real pty (no process tree, but real devices)

HANG = 30.0  # seconds: only bounds a hang, never a performance budget
VMAX = P.MAX_SPEED_STEPS_PER_S * RAD_PER_STEP  # rad/s
# How long the driver waits for answers: generous, because on a loaded machine the emulator's
# thread may be starved for a while, and a servo that answers late must not count as silent.
ANSWER = 0.5


def wait_for(predicate, what, timeout=HANG, step=None):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if step is not None:
            step()
        if predicate():
            return
        time.sleep(0.002)
    raise AssertionError(f"timed out waiting for {what}")


# -- the bus -----------------------------------------------------------------------------------
def test_ping_read_write_sync(emulator):
    with FeetechBus(emulator.path, timeout=ANSWER) as bus:
        assert [bus.ping(i) for i in range(1, 7)] == [P.STS3215_MODEL] * 6
        bus.write(2, Reg.GOAL_SPEED, -300)
        assert bus.read(2, Reg.GOAL_SPEED) == -300
        assert bus.sync_read(Reg.PRESENT_POSITION, range(1, 7)) == {i: 2048 for i in range(1, 7)}
        bus.sync_write(Reg.GOAL_POSITION, {i: 1000 + i for i in range(1, 7)})
        assert bus.sync_read(Reg.GOAL_POSITION, range(1, 7)) == {i: 1000 + i for i in range(1, 7)}
        assert bus.dropped_bytes == 0 and emulator.bad_packets == 0


def test_silent_servo_is_named(emulator):
    emulator.set_silent(4)
    with FeetechBus(emulator.path, timeout=ANSWER) as bus:
        with pytest.raises(FeetechNoAnswer, match="servo 4 did not answer PING") as err:
            bus.ping(4)
        assert err.value.ids == [4]
        assert set(bus.sync_read(Reg.PRESENT_POSITION, range(1, 7))) == {1, 2, 3, 5, 6}


def test_missing_port_is_named(tmp_path):
    missing = str(tmp_path / "ttyUSB99")
    with pytest.raises(FeetechPortError, match="ttyUSB99"):
        FeetechBus(missing).open()
    with pytest.raises(FeetechPortError, match="ttyUSB99"):
        ServoArm(missing).start()


def test_taken_port_is_named(emulator):
    with FeetechBus(emulator.path, timeout=ANSWER):
        with pytest.raises(FeetechPortError, match="taken by another program") as err:
            FeetechBus(emulator.path, timeout=ANSWER).open()
        assert emulator.path in str(err.value)


def test_garbage_on_the_line_is_dropped_not_read(emulator):
    with FeetechBus(emulator.path, timeout=ANSWER) as bus:
        emulator.glitch_next_answer(b"\xff\xff\x01\x09\x00gar\xff\xff\x02bage")  # noise before the servos answer
        assert bus.sync_read(Reg.PRESENT_POSITION, [1, 2]) == {1: 2048, 2: 2048}
        assert bus.dropped_bytes == 15  # every noise byte, and nothing else
        bus._serial.write(b"\x00\xff\x13\xff\xff\xfe")  # noise toward the servos: they resync too
        assert bus.ping(3) == P.STS3215_MODEL
        assert emulator.bad_packets > 0


# -- the arm: goals reached at the servos' speed limit, a silent servo, unplug/replug ------------
def test_arm_reaches_goals_at_the_speed_limit(emulator):
    arm = ServoArm(emulator.path, timeout=ANSWER)
    arm.start()
    try:
        assert arm.lost == {}
        samples = []  # (wall time before the cycle, wall time after, elbow position)
        targets = {"elbow_flex": 1.0, "wrist_roll": -0.5}

        def step():
            before = time.monotonic()
            reading = arm.cycle(targets)
            samples.append((before, time.monotonic(), reading))

        def there():
            r = samples[-1][2]
            pos = dict(zip(r.names, r.position, strict=True))
            return abs(pos["elbow_flex"] - 1.0) <= RAD_PER_STEP and abs(pos["wrist_roll"] + 0.5) <= RAD_PER_STEP

        wait_for(there, "the elbow and wrist to reach their goals", step=step)
        last = samples[-1][2]
        assert last.names == list(SO100_JOINTS)
        assert last.position[0] == 0.0 and abs(last.position[2] - 1.0) <= RAD_PER_STEP
        # No servo ever moved faster than the STS3215's 0.222 s / 60 deg: between two readings it
        # covered at most VMAX x the widest wall time that can separate them (+1 step of rounding).
        elbow = [(b, a, r.position[2]) for b, a, r in samples]
        for (b0, _a0, p0), (_b1, a1, p1) in zip(elbow, elbow[1:], strict=False):
            assert abs(p1 - p0) <= VMAX * (a1 - b0) + RAD_PER_STEP
        assert abs(elbow[-1][2] - elbow[0][2]) <= VMAX * (elbow[-1][1] - elbow[0][0]) + RAD_PER_STEP
        moving = [r.velocity[2] for _b, _a, r in samples if 0.1 < r.position[2] < 0.9]
        assert moving and all(0 < v <= VMAX + 1e-9 for v in moving)
    finally:
        arm.stop()


def test_silent_servo_others_keep_working(emulator):
    emulator.set_silent(3)
    arm = ServoArm(emulator.path, timeout=ANSWER, reping_period=0.5)
    arm.start()
    try:
        assert list(arm.lost) == [3] and "servo 3 (elbow_flex)" in arm.lost[3] and emulator.path in arm.lost[3]
        reading = arm.cycle({"gripper": 0.2})
        assert reading.names == ["shoulder_pan", "shoulder_lift", "wrist_flex", "wrist_roll", "gripper"]
        wait_for(lambda: abs(arm.cycle().position[-1] - 0.2) <= RAD_PER_STEP, "the gripper to move without servo 3")
        emulator.set_silent(3, False)
        wait_for(lambda: "elbow_flex" in arm.cycle().names, "servo 3 to be pinged back in")
        assert arm.lost == {}
    finally:
        arm.stop()


def test_no_servo_answering_fails_start_naming_them(emulator):
    for i in range(1, 7):
        emulator.set_silent(i)
    with pytest.raises(FeetechNoAnswer, match="no servo answered.*servo 1 \\(shoulder_pan\\)"):
        ServoArm(emulator.path, timeout=0.05).start()  # all silent: a short wait loses nothing


# -- the component -----------------------------------------------------------------------------
def _component(emulator, **kw):
    return FeetechArm("arm", FeetechArmConfig(port=emulator.path, response_timeout=ANSWER, **kw))


def _states_until(h, predicate, what):
    seen = []

    def step():
        h.advance(0.01)
        seen.extend(h.outputs("joint_states"))

    wait_for(lambda: bool(seen) and predicate(seen[-1]), what, step=step)
    return seen[-1]


def test_component_publishes_joint_states_and_follows_commands(emulator):
    with ComponentHarness(_component(emulator)) as h:
        msg = _states_until(h, lambda m: True, "a first JointState")
        assert msg.name == list(SO100_JOINTS) and np.allclose(msg.position, 0.0)
        assert h.health.level == HealthLevel.HEALTHY
        h.feed("joint_command", JointState(name=["shoulder_pan", "gripper"], position=np.array([0.5, -0.3])))
        msg = _states_until(h, lambda m: abs(m.position[0] - 0.5) <= RAD_PER_STEP and abs(m.position[5] + 0.3) <= RAD_PER_STEP,
                            "the commanded JointState")
        assert emulator.servos[1].get(Reg.GOAL_POSITION) == 2048 + round(0.5 / RAD_PER_STEP)
        # unknown joints and NaN are refused, naming them; the rest of the command still applies
        h.feed("joint_command", JointState(name=["Jaw", "wrist_flex", "elbow_flex"], position=np.array([1.0, 0.1, math.nan])))
        _states_until(h, lambda m: abs(m.position[3] - 0.1) <= RAD_PER_STEP, "the valid part of a partly bad command")
        assert h.component.bad_commands == 1 and emulator.servos[3].get(Reg.GOAL_POSITION) == 2048


def test_component_follows_a_joint_trajectory(emulator):
    """The VLA component may publish a JointTrajectory instead: its last point is the goal."""
    comp = _component(emulator)
    comp.inputs(joint_command=Topic(name="joint_trajectory", msg_type="JointTrajectory"))
    with ComponentHarness(comp) as h:
        h.feed("joint_trajectory", JointTrajectory(joint_names=["elbow_flex", "wrist_flex"], points=[
            JointTrajectoryPoint(positions=np.array([0.3, 0.3])), JointTrajectoryPoint(positions=np.array([-0.25, 0.2]))]))
        msg = _states_until(h, lambda m: abs(m.position[2] + 0.25) <= RAD_PER_STEP, "the trajectory's goal")
        assert abs(msg.position[3] - 0.2) <= RAD_PER_STEP


def test_component_with_the_simulated_arms_joint_names(emulator):
    """The VLA recipe's joint map (the simulated SO-101's names) works unchanged when the servos are named so."""
    sim_names = {"Rotation": 1, "Pitch": 2, "Elbow": 3, "Wrist_Pitch": 4, "Wrist_Roll": 5, "Jaw": 6}
    with ComponentHarness(_component(emulator, joints=sim_names)) as h:
        h.feed("joint_command", JointState(name=["Elbow"], position=np.array([0.4])))
        msg = _states_until(h, lambda m: abs(m.position[2] - 0.4) <= RAD_PER_STEP, "the Elbow to move")
        assert msg.name == list(sim_names)


def test_component_silent_servo_named_in_health(emulator):
    emulator.set_silent(5)
    with ComponentHarness(_component(emulator)) as h:
        msg = _states_until(h, lambda m: True, "a JointState")
        assert "wrist_roll" not in msg.name and len(msg.name) == 5
        assert h.health.level == HealthLevel.COMPONENT_FAILURE
        assert "servo 5 (wrist_roll)" in h.health.message and emulator.path in h.health.message


def test_component_unplug_reports_port_and_resumes(emulator):
    with ComponentHarness(_component(emulator)) as h:
        _states_until(h, lambda m: True, "a JointState")
        emulator.unplug()
        wait_for(lambda: h.health.level == HealthLevel.SYSTEM_FAILURE, "SYSTEM_FAILURE", step=lambda: h.advance(0.01))
        assert emulator.path in h.health.message
        # the ladder retries (on the wall clock: the device's time) against the missing port
        wait_for(lambda: "reconnect attempt 2 failed" in h.health.message, "two failed reconnect attempts",
                 step=lambda: h.advance(0.01))
        assert h.health.level == HealthLevel.SYSTEM_FAILURE and "ttyFEETECH" in h.health.message
        h.outputs("joint_states")
        emulator.replug()
        _states_until(h, lambda m: len(m.name) == 6, "JointStates again after the replug")
        wait_for(lambda: h.health.level == HealthLevel.HEALTHY, "HEALTHY after the replug", step=lambda: h.advance(0.01))
        assert h.component.arm_status()["reconnects"] == 1


def test_component_bad_port_fails_activation_naming_it(tmp_path):
    comp = FeetechArm("arm", FeetechArmConfig(port=str(tmp_path / "ttyACM7")))
    with pytest.raises(Exception, match="ttyACM7"):
        ComponentHarness(comp)


def test_config_refuses_bad_joint_maps():
    with pytest.raises(ValueError, match="share a servo id"):
        FeetechArmConfig(joints={"a": 1, "b": 1})
    with pytest.raises(ValueError, match="ids integers"):
        FeetechArmConfig(joints={"a": 300})


def test_cycle_rate_benchmark_runs():
    result = servo_cycle_hz(seconds=0.3, timeout=ANSWER)
    assert result["cycles"] > 0 and result["incomplete_cycles"] == 0 and result["dropped_bytes"] == 0
