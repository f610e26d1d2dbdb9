"""Keyed inputs/outputs (Kompass-style) and the launcher's shared wiring."""
import enum
from collections.abc import Mapping
from typing import ClassVar

import pytest

from emos import Launcher, Topic
from emos.core.keyed import AllowedTopic, KeyedComponent

pytestmark = pytest.mark.process


class Keys(str, enum.Enum):
    PLAN = "plan"


class Follower(KeyedComponent):
    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "plan": AllowedTopic(types=("Path",), default=Topic(name="/plan", msg_type="Path")),
        "location": AllowedTopic(types=("Odometry", "PoseStamped"), default=Topic(name="/odom", msg_type="Odometry")),
        "vision": AllowedTopic(types=("Detections",)),
    }
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {"command": AllowedTopic(types=("Twist", "TwistStamped"), default=Topic(name="/control", msg_type="Twist"), required=True)}


def test_defaults_and_replacement_by_key():
    f = Follower(component_name="follower")
    assert [t.name for t in f.in_topics] == ["/plan", "/odom"]
    assert f.get_in_topic(Keys.PLAN).name == "/plan"
    assert f.get_in_topic("vision") is None
    f.inputs(location=Topic(name="/odometry/filtered", msg_type="PoseStamped"))
    assert [t.name for t in f.in_topics] == ["/plan", "/odometry/filtered"]
    f.outputs(command=Topic(name="/cmd_vel", msg_type="TwistStamped"))
    assert [t.name for t in f.out_topics] == ["/cmd_vel"]


def test_trigger_follows_its_key():
    f = Follower(component_name="follower")
    f.trigger = f.get_in_topic("plan")
    f.inputs(plan=Topic(name="/other_plan", msg_type="Path"))
    assert [t.name for t in f.trigger] == ["/other_plan"]
    assert "/plan" not in [t.name for t in f.in_topics]


def test_wrong_key_and_wrong_type_fail_naming_both():
    f = Follower(component_name="follower")
    with pytest.raises(KeyError, match="no input key 'goal'.*location, plan, vision"):
        f.inputs(goal=Topic(name="/goal", msg_type="PoseStamped"))
    with pytest.raises(TypeError, match=r"input 'location' accepts Odometry or PoseStamped.*'/scan' is LaserScan"):
        f.inputs(location=Topic(name="/scan", msg_type="LaserScan"))
    with pytest.raises(ValueError, match="at most 1"):
        f.inputs(plan=[Topic(name="/a", msg_type="Path"), Topic(name="/b", msg_type="Path")])
    with pytest.raises(ValueError, match="required"):
        f.outputs(command=None)
    with pytest.raises(TypeError, match="given by key"):
        Follower(component_name="f2", inputs=[Topic(name="/plan", msg_type="Path")])


def test_launcher_shared_inputs_and_unknown_key():
    a, b = Follower(component_name="a"), Follower(component_name="b")
    launcher = Launcher()
    launcher.kompass(components=[a, b], multiprocessing=False)
    launcher.inputs(location=Topic(name="/odometry/filtered", msg_type="Odometry"))
    launcher._apply_shared()
    assert a.get_in_topic("location").name == b.get_in_topic("location").name == "/odometry/filtered"
    launcher.inputs(no_such_key=Topic(name="/x", msg_type="String"))
    with pytest.raises(ValueError, match="no_such_key"):
        launcher._apply_shared()
