"""emos.testing.ComponentHarness: a component's real node, driven by hand on a manual clock."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos import BaseComponent, Topic
from emos import msgs as M
from emos.core import clock
from emos.testing import ComponentHarness
from emos.transport.context import SHM_DIR

pytestmark = pytest.mark.unit


class Counter(BaseComponent):
    """Timed: counts its steps and publishes the count; remembers the clock at each step."""

    def custom_on_activate(self) -> None:
        self.n, self.times = 0, []

    def _execution_step(self) -> None:
        self.n += 1
        self.times.append(clock.now())
        self.publish("/count", M.Int32(data=self.n))
        self.health_status.set_healthy()


class Echo(BaseComponent):
    """Event: one step per message on /in; reports the age of /other at each step."""

    def custom_on_activate(self) -> None:
        self.ages = []

    def _execution_step(self, msg=None, topic=None) -> None:
        if msg.data < 0:
            raise ValueError("negative input")
        self.ages.append(self.input_age("/other"))
        self.publish("/out", M.Int32(data=msg.data * 2))
        self.health_status.set_healthy()


def _segments(ctx_prefix: str) -> list[str]:
    return [p.name for p in SHM_DIR.iterdir() if p.name.startswith(ctx_prefix)]


def test_a_timed_component_steps_once_per_tick_on_the_manual_clock():
    c = Counter(component_name="counter", outputs=[Topic(name="count", msg_type="Int32")])
    c.config.loop_rate = 10.0
    with ComponentHarness(c, start_time=100.0) as h:
        prefix = h._ctx.shm_prefix
        assert _segments(prefix), "the harness runs on real rings"
        h.advance(1.0)
        assert c.n == 10 and [m.data for m in h.outputs("count")] == list(range(1, 11))
        assert c.times == pytest.approx([100.1 + 0.1 * i for i in range(10)])
        assert clock.now() == pytest.approx(101.0) and h.time == pytest.approx(101.0)
        h.advance(0.05)  # half a period: no step is due
        assert c.n == 10 and h.outputs("count") == []
        h.advance(0.05)
        assert c.n == 11 and h.latest("count").data == 11
        assert h.health.is_healthy
    assert not _segments(prefix)  # every ring of the harness's run is gone
    assert abs(clock.now() - __import__("time").time()) < 60  # the process is back on the wall clock


def test_an_event_component_steps_on_what_is_fed_and_ages_follow_the_manual_clock():
    c = Echo(component_name="echo", inputs=[Topic(name="in", msg_type="Int32"), Topic(name="other", msg_type="Int32")],
             outputs=[Topic(name="out", msg_type="Int32")])
    c.trigger = c.in_topics[0]
    with ComponentHarness(c) as h:
        h.feed("/other", M.Int32(data=0))
        h.advance(2.5)  # nothing on the trigger: no step
        assert h.outputs("/out") == [] and c.ages == []
        h.feed("in", M.Int32(data=4))
        h.feed("in", M.Int32(data=5))
        h.step()
        assert [m.data for m in h.outputs("/out")] == [8, 10]
        assert c.ages == [pytest.approx(2.5), pytest.approx(2.5)]  # simulated seconds, whatever the wall clock did
        h.feed("in", M.Int32(data=-1))
        h.step()
        assert h.health.is_component_fail and "negative input" in h.health.to_msg().message


def test_bad_use_is_refused_naming_the_thing():
    c = Counter(component_name="counter", outputs=[Topic(name="count", msg_type="Int32")])
    with pytest.raises(ValueError, match="start_time must be a finite time >= 0 s, got nan"):
        ComponentHarness(c, start_time=math.nan)
    with pytest.raises(ValueError, match="tick must be a finite period > 0 s, got 0"):
        ComponentHarness(c, tick=0)
    with ComponentHarness(c) as h:
        with pytest.raises(KeyError, match="component 'counter' has no input '/nope'; inputs: "):
            h.feed("nope", M.Int32(data=1))
        with pytest.raises(KeyError, match="has no output '/nope'; outputs: \\['/count'\\]"):
            h.outputs("/nope")
        with pytest.raises(ValueError, match="advance takes a finite number of seconds >= 0, got -1"):
            h.advance(-1)
        with pytest.raises(RuntimeError, match="already running"):
            ComponentHarness(c)
    with pytest.raises(TypeError, match="drives a BaseComponent, got str"):
        ComponentHarness("counter")


# ------------------------------------------------------------------ the DriveManager, on robot time

def _robot():
    from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType

    return RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                       geometry_params=np.array([0.15, 0.3]),
                       ctrl_vx_limits=LinearCtrlLimits(max_vel=0.5, max_acc=1.5, max_decel=2.5),
                       ctrl_omega_limits=AngularCtrlLimits(max_vel=1.5, max_acc=3.0, max_decel=3.0))


def _open_room_inputs(h: ComponentHarness) -> None:
    """What a base standing in the middle of an empty 10 m room publishes."""
    odom = M.Odometry()
    odom.header.frame_id = "map"
    odom.pose.pose.position.x, odom.pose.pose.position.y = 5.0, 5.0
    odom.pose.pose.orientation = M.Quaternion.from_yaw(0.0)
    h.feed("/odom", odom)
    h.feed("/scan", M.LaserScan(angle_min=-math.pi, angle_max=math.pi - math.pi / 180, angle_increment=math.pi / 180,
                                range_min=0.05, range_max=10.0, ranges=np.full(360, 5.0, dtype=np.float32)))


def _drive_for(h: ComponentHarness, seconds: float) -> list[float]:
    """The controller keeps asking for 0.2 m/s at every tick; returns the speeds sent to the base."""
    sent: list[float] = []
    end = h.time + seconds
    while h.time < end - 1e-9:
        _open_room_inputs(h)
        h.feed("/control", M.Twist(linear=M.Vector3(x=0.2)))
        h.advance(h.tick)
        sent += [c.linear.x for c in h.outputs("/cmd_vel")]
    return sent


def test_the_drive_manager_holds_the_robot_for_stop_hold_time_whatever_the_controller_sends():
    from emos.actors.nav.components import DriveManager, DriveManagerConfig

    driver = DriveManager(component_name="driver", config=DriveManagerConfig(robot=_robot(), stop_hold_time=1.0, loop_rate=20.0))
    with ComponentHarness(driver, start_time=10.0) as h:
        assert max(_drive_for(h, 1.0)) > 0.15  # it drives
        assert driver.stop() is True
        held = _drive_for(h, 0.95)
        assert held and all(v == 0.0 for v in held)  # commands kept coming at 20 Hz, the robot stood
        after = _drive_for(h, 0.5)
        assert max(after) > 0.1  # driving again once the hold of 1.0 robot-seconds is over
