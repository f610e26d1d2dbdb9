"""The DriveManager's prioritised command inputs (ROS 2's twist_mux) and its speed-zone cap.

The real DriveManager node runs in ``emos.testing.ComponentHarness`` on robot time, with the
kinematic room base of the DriveManager's robot-time tests answering every tick: a controller
publishes on ``/control`` every tick while a recovery behavior publishes on its own, higher
input; the commands sent to ``/cmd_vel`` show which input drove when.
"""
from __future__ import annotations

import numpy as np
import pytest

from emos import Topic
from emos import msgs as M
from emos.actors.nav.components.drive_manager import CommandInput, DriveManagerConfig
from emos.core.lifecycle import InvalidTransition
from emos.errors import ConfigError
from emos.testing import ComponentHarness
from tests.nav.components.test_drive_manager_on_robot_time import RoomBase, _driver

pytestmark = pytest.mark.unit

MUX = [CommandInput(topic="/control", priority=10, timeout=0.3), CommandInput(topic="/control/behaviors", priority=20, timeout=0.5)]


class TwoSources(RoomBase):
    """The room base, a controller that drives forward at 0.2 m/s every tick on ``/control``,
    and a behavior that backs up at 0.1 m/s on ``/control/behaviors`` while ``behaving``."""

    def __init__(self, start) -> None:
        super().__init__(start)
        self.control = M.Twist(linear=M.Vector3(x=0.2))
        self.behaving = False

    def __call__(self, h: ComponentHarness) -> None:
        super().__call__(h)
        if self.behaving:
            h.feed("/control/behaviors", M.Twist(linear=M.Vector3(x=-0.1)))


def test_a_live_higher_input_drives_and_a_silent_one_releases_the_robot_to_the_next():
    driver = _driver(loop_rate=20.0, command_inputs=MUX)
    base = TwoSources(start=(1.0, 3.2, 0.0))
    with ComponentHarness(driver, start_time=10.0) as h:
        h.advance(1.0, each_tick=base)
        assert max(c.linear.x for c in h.outputs("/cmd_vel")) > 0.15  # the controller drives
        base.behaving = True
        h.advance(1.0, each_tick=base)
        sent = [c.linear.x for c in h.outputs("/cmd_vel")]
        # The behavior took over within a tick or two and the controller's every-tick commands
        # were ignored from then on: never forward again while the behavior spoke.
        took_over = next(i for i, v in enumerate(sent) if v < 0.0)
        assert took_over <= 8 and all(v <= 1e-9 for v in sent[took_over:]) and min(sent) < -0.05
        base.behaving = False
        h.advance(0.4, each_tick=base)  # under the behavior's 0.5 s timeout: it still holds (its last word)
        assert all(c.linear.x <= 1e-9 for c in h.outputs("/cmd_vel"))
        h.advance(1.0, each_tick=base)  # past it: released, the controller drives again
        assert max(c.linear.x for c in h.outputs("/cmd_vel")) > 0.15
        assert h.health.is_healthy


def test_a_lower_input_never_drives_while_a_higher_one_is_live():
    driver = _driver(loop_rate=20.0, command_inputs=MUX)
    base = TwoSources(start=(1.0, 3.2, 0.0))
    base.behaving = True
    with ComponentHarness(driver, start_time=10.0) as h:
        h.advance(1.5, each_tick=base)
        assert all(c.linear.x <= 1e-9 for c in h.outputs("/cmd_vel"))


def test_the_default_is_the_one_control_input():
    driver = _driver()
    assert [t.name for t in driver.get_in_topics("command")] == ["/control"]
    muxed = _driver(command_inputs=MUX)
    assert [t.name for t in muxed.get_in_topics("command")] == ["/control", "/control/behaviors"]
    assert set(muxed.trigger) >= set(muxed.get_in_topics("command"))  # every input steps the DriveManager


@pytest.mark.parametrize("inputs, message", [
    ([CommandInput("/a", 1, 0.3), CommandInput("a", 2, 0.3)], r"command_inputs\[1\]\.topic: 'a' is already command_inputs\[0\]'s topic"),
    ([CommandInput("/a", 1, 0.3), CommandInput("/b", 1, 0.3)], r"command_inputs\[1\]\.priority: 1 is already the priority of command_inputs\[0\] \(/a\)"),
    ([CommandInput("/a", 1, 0.0)], r"command_inputs\[0\]\.timeout: expected a number of seconds > 0, got 0"),
    ([CommandInput("/a", 1, -0.5)], r"command_inputs\[0\]\.timeout: expected a number of seconds > 0, got -0.5"),
    ([CommandInput("/a", 1, float("inf"))], r"command_inputs\[0\]\.timeout"),
    ([CommandInput("/a", 1.5, 0.3)], r"command_inputs\[0\]\.priority: expected an integer, got 1.5"),
    ([{"topic": "/a", "priority": 1}], r"command_inputs\[0\]: expected the keys topic, priority, timeout"),
    ([CommandInput("/a", 1, 0.3, msg_type="Odometry")], r"command_inputs\[0\]\.msg_type"),
])
def test_a_bad_command_input_is_refused_where_the_config_is_made(inputs, message):
    with pytest.raises(ValueError, match=message):
        DriveManagerConfig(command_inputs=inputs)


def test_inputs_rewired_away_from_command_inputs_are_refused_at_configure():
    driver = _driver(command_inputs=MUX)
    driver.inputs(command=Topic(name="/teleop", msg_type="Twist"))
    refused = pytest.raises((ConfigError, InvalidTransition), match=r"/control, /control/behaviors not wired.*/teleop has no command_inputs entry")
    with refused, ComponentHarness(driver):
        pass


def test_a_behavior_command_obeys_a_speed_zone(tmp_path):
    from emos.actors.nav.costmap import Zone
    from emos.actors.nav.costmap.mask_io import write_mask
    from tests.costmap.helpers import room_grid

    # A 10 % zone (0.05 m/s for this robot's 0.5 m/s) over the left of the room, where the robot is.
    zone = Zone(name="hall", kind="speed", polygon=((0.0, 0.0), (2.5, 0.0), (2.5, 4.0), (0.0, 4.0)), value=10.0)
    mask = str(write_mask(tmp_path / "speed.yaml", [zone], "speed_percent", room_grid()))

    def top_speed(**config) -> float:
        base = TwoSources(start=(1.0, 3.2, np.pi))  # facing the wall: backing up goes into the open room
        base.control = None
        base.behaving = True
        with ComponentHarness(_driver(loop_rate=20.0, command_inputs=MUX, **config), start_time=10.0) as h:
            h.advance(1.0, each_tick=base)
            return max(abs(c.linear.x) for c in h.outputs("/cmd_vel"))

    assert top_speed() > 0.09  # no mask: the behavior's 0.1 m/s
    assert top_speed(speed_mask=mask) <= 0.05 + 1e-9  # in the zone: capped, whichever input sent it
