"""Plugin declarations are checked when the class is defined, configs when they are built;
what a plugin offers is listed without opening anything (``emos robot inspect``); its events
are ordinary Events and its actions ordinary component Actions."""
from __future__ import annotations

import json
from collections.abc import Mapping
from typing import ClassVar

import pytest

from emos.actors.hardware.create2.component import Create2Base, Create2Config
from emos.actors.hardware.feetech.component import FeetechArm, FeetechArmConfig
from emos.actors.hardware.plugin import Command, Feedback, PluginEvent, RobotPlugin, plugin_action
from emos.actors.hardware.plugin.registry import UnknownPlugin, describe, find_plugin
from emos.actors.hardware.rplidar.component import Rplidar, RplidarConfig
from emos.events import Action, Event
from emos.io.topic import Topic

pytestmark = pytest.mark.unit


def test_an_event_on_feedback_the_plugin_lacks_is_refused_at_class_definition():
    with pytest.raises(TypeError, match=r"event 'bump' watches feedback 'bumper'.*\['odom'\]"):
        class Bad(RobotPlugin):
            feedback: ClassVar[Mapping[str, Feedback]] = {"odom": Feedback(msg_type="Odometry", topic="/odom")}
            plugin_events: ClassVar[Mapping[str, PluginEvent]] = {"bump": PluginEvent(feedback="bumper", condition=lambda t: t.msg.data == True)}  # noqa: E712


def test_a_watchdog_in_a_config_field_that_does_not_exist_is_refused():
    with pytest.raises(TypeError, match="watchdog in config field 'cmd_timeout'"):
        class Bad(RobotPlugin):
            commands: ClassVar[Mapping[str, Command]] = {"command": Command(msg_types=("Twist",), topic="/cmd_vel", timeout="cmd_timeout")}


def test_private_plugin_actions_are_refused():
    with pytest.raises(ValueError, match="public"):
        @plugin_action("hidden")
        def _secret(self):
            pass


@pytest.mark.parametrize("make", [
    lambda: Create2Config(cmd_timeout=-1.0),
    lambda: Create2Config(port=""),
    lambda: Create2Config(cmd_timeout=float("nan")),
    lambda: RplidarConfig(bins=3),
    lambda: RplidarConfig(motor_pwm=5000),
    lambda: FeetechArmConfig(joints={"a": 1, "b": 1}),
    lambda: Create2Base(port=""),
])
def test_bad_driver_configs_fail_at_definition_naming_the_field(make):
    with pytest.raises((ValueError, TypeError)):
        make()


def test_config_fields_are_validated_on_set_too():
    cfg = Create2Config()
    with pytest.raises(ValueError):
        cfg.cmd_timeout = 0.0
    assert cfg.cmd_timeout == 0.5


def test_keys_match_the_simulators_so_a_recipe_swaps_one_for_the_other():
    from emos.actors.sim import Simulator

    base, lidar = Create2Base(port="/dev/null"), Rplidar(config=RplidarConfig(port="/dev/null"))
    for key in base.allowed_inputs:
        assert key in Simulator.allowed_inputs
    for key in list(base.allowed_outputs)[:1] + list(lidar.allowed_outputs):
        assert key in Simulator.allowed_outputs
    base.inputs(command=Topic(name="/nav/cmd", msg_type="Twist"))
    assert [t.name for t in base.trigger] == ["/nav/cmd"]  # the command trigger follows its key


def test_plugin_events_are_events_on_the_plugins_topics_and_actions_component_actions():
    base = Create2Base(port="/dev/null")
    base.outputs(bumper=Topic(name="/base/bumper", msg_type="Bool"))
    ev = base.event("bump")
    assert isinstance(ev, Event) and ev.on_change and ev.name == "create2.bump"
    assert "/base/bumper" in json.dumps(ev.to_dict())
    with pytest.raises(KeyError, match="its events are: bump, low_battery"):
        base.event("fall")
    action = Action(method=base.stop_base)
    assert action.kind == "component" and action.component == "create2"
    assert set(Create2Base.plugin_actions) == {"stop_base", "set_oi_mode", "seek_dock"}
    assert set(FeetechArm.plugin_actions) == {"set_torque", "arm_status"}


def test_describe_lists_topics_actions_events_transports_config_and_robot():
    info = describe(find_plugin("create2"))
    assert info["feedback"]["battery"] == {"topic": "/battery", "type": "BatteryState", "help": info["feedback"]["battery"]["help"]}
    assert info["commands"]["command"]["watchdog"] == "cmd_timeout"
    assert info["transports"]["serial"] == {"kind": "serial", "device": "Create 2", "address": "'/dev/ttyUSB0'", "baudrate": 115200}
    assert info["config"]["fields"]["cmd_timeout"] == 0.5 and set(info["events"]) == {"bump", "low_battery"}
    assert info["robot_config"]["wheel_base"] == pytest.approx(0.235)
    lidar = describe(find_plugin("rplidar"))
    assert lidar["transports"]["serial"]["via"] == "driver session" and "lidar_stats" in lidar["actions"]
    assert describe(find_plugin("emos.actors.hardware.feetech.component:FeetechArm"))["name"] == "feetech"
    with pytest.raises(UnknownPlugin, match="create2, feetech, rplidar"):
        find_plugin("roomba")
    with pytest.raises(UnknownPlugin, match="not a RobotPlugin"):
        find_plugin("emos.io.topic:Topic")
