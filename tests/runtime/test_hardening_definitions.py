"""Issue 9, probes 8-10: what is wrong in a recipe is refused when it is defined, with the limit."""
import logging
import re
import subprocess
import sys

import pytest

from emos import BaseComponent, Launcher, Topic
from emos.config import ConfigError
from emos.core.wiring import TopicTypeConflict, warn_unused_config_sections
from emos.supervisor.system import Package, System
from emos.transport.limits import component_name_limit, segment_name_limit
from tests.runtime.helpers import RECIPE_HEADER

pytestmark = pytest.mark.process


def test_two_components_declaring_one_topic_with_two_types_are_refused_at_bringup():
    a = BaseComponent(component_name="talker", outputs=[Topic(name="/shared", msg_type="String")])
    b = BaseComponent(component_name="viewer", inputs=[Topic(name="shared", msg_type="Image")])
    launcher = Launcher(multi_processing=True)
    launcher.add_pkg(components=[a, b])
    with pytest.raises(TopicTypeConflict) as err:
        launcher.bringup()
    msg = str(err.value)
    for part in ("'/shared'", "std_msgs/msg/String", "sensor_msgs/msg/Image", "'talker'", "'viewer'"):
        assert part in msg


def test_a_topic_named_like_a_status_topic_must_carry_component_status():
    a = BaseComponent(component_name="planner")
    b = BaseComponent(component_name="spy", inputs=[Topic(name="/planner/status", msg_type="String")])
    launcher = Launcher()
    launcher.add_pkg(components=[a, b])
    with pytest.raises(TopicTypeConflict, match="'/planner/status'.*ComponentStatus.*'planner'.*String.*'spy'"):
        launcher.bringup()


def test_an_80_character_component_name_is_refused_with_the_socket_limit():
    limit = component_name_limit()
    assert 20 < limit < 80
    with pytest.raises(ValueError, match=rf"is 80 characters; at most {limit} fit.*AF_UNIX.*sun_path"):
        BaseComponent(component_name="c" * 80)
    BaseComponent(component_name="c" * limit)  # the limit itself is fine


def test_a_300_character_topic_name_is_refused_with_the_shm_name_limit():
    limit = segment_name_limit()
    with pytest.raises(ValueError, match=rf"is 300 bytes as a file name; at most {limit} fit.*NAME_MAX \(255 bytes\)"):
        Topic(name="t" * 300, msg_type="String")
    Topic(name="t" * limit, msg_type="String")  # the limit itself is fine
    with pytest.raises(ValueError, match="NAME_MAX"):
        Topic(name="t" * (limit + 1), msg_type="String")


def test_the_longest_names_allowed_really_work(ctx):
    """The limits are real: a publisher with the longest component name on the longest topic."""
    from emos.msgs import String
    from emos.transport.pubsub import Publisher, Subscriber

    name = "p" * component_name_limit()
    topic = "/" + "t" * segment_name_limit(name)
    pub = Publisher(ctx, topic, String, publisher_id=name)
    sub = Subscriber(ctx, topic, String)
    try:
        pub.publish(String(data="x"))
        assert [m.data for m in sub.take()] == ["x"]
        assert len(pub.segment) <= 255
    finally:
        sub.close()
        pub.close()


def test_misspelled_and_scalar_config_sections_are_reported_with_close_matches(tmp_path, caplog):
    path = tmp_path / "params.yaml"
    path.write_text("/**:\n  loop_rate: 5.0\nplaner:\n  loop_rate: 2.0\nheartbeat_rate: 3\ncontroller:\n  loop_rate: 4.0\n")
    comps = [BaseComponent(component_name="planner", config_file=str(path)), BaseComponent(component_name="controller", config_file=str(path))]
    with caplog.at_level(logging.WARNING, logger="emos.config"):
        problems = warn_unused_config_sections(comps)
        caplog.clear()
        System([Package(components=comps, multiprocessing=False)])  # what bringup builds: it warns too
    assert len(problems) == 2
    assert "section 'planer' matches no component" in problems[0] and "did you mean 'planner'" in problems[0]
    assert "top-level key 'heartbeat_rate' holds a int (3), not a section" in problems[1]
    assert "did you mean 'planner'" in caplog.text and "'heartbeat_rate' holds a int" in caplog.text


def test_a_scalar_where_a_components_parameters_belong_is_refused_at_definition_and_reported_at_bringup(tmp_path):
    path = tmp_path / "params.yaml"
    path.write_text("/**:\n  loop_rate: 3.0\ncam: 5\n")
    refused = r"params.yaml: 'cam' is the section of component cam and must be a mapping of parameters \(name: value\), got int 5"
    with pytest.raises(ConfigError, match=refused):
        BaseComponent(component_name="cam", config_file=str(path))
    with pytest.raises(ConfigError, match=refused):
        Launcher(config_file=str(path)).add_pkg(components=[BaseComponent(component_name="cam")])
    # A component that reads the same file for its own parameters loads it; bring-up names the
    # scalar that its neighbour 'cam' (configured otherwise) would never see.
    other = BaseComponent(component_name="other", config_file=str(path))
    assert other.config.loop_rate == 3.0
    problems = warn_unused_config_sections([other, BaseComponent(component_name="cam")])
    assert len(problems) == 1 and "'cam' is the section of component cam" in problems[0] and "ignored" in problems[0]
    common = tmp_path / "common.toml"
    common.write_text('"/**" = 5\n')
    with pytest.raises(ConfigError, match=r"'/\*\*' is the section every component reads and must be a mapping"):
        BaseComponent(component_name="cam", config_file=str(common))


@pytest.mark.parametrize("name", ["{x}", "~x", "~/scan", "robot/{ns}/scan", "a~b", "a b", "scan/", "//scan", "1scan", "sc-an"])
def test_topic_names_hold_letters_digits_and_underscores_only(name):
    with pytest.raises(ValueError, match=f"Topic name {re.escape(repr(name))} is invalid"):
        Topic(name=name, msg_type="String")


def test_ros_substitutions_in_topic_names_are_refused_with_the_reason():
    with pytest.raises(ValueError, match=r"ROS substitutions .* are not expanded by EMOS"):
        Topic(name="~/scan", msg_type="LaserScan")
    assert Topic(name="robot_1/scan_2", msg_type="LaserScan").name == "/robot_1/scan_2"


def _emos_run(tmp_path, body: str, *extra: str) -> subprocess.CompletedProcess:
    script = tmp_path / "recipe.py"
    script.write_text(RECIPE_HEADER + body)
    return subprocess.run([sys.executable, "-m", "emos", "run", str(script), *extra], capture_output=True, text=True, timeout=60, cwd=tmp_path)


@pytest.mark.parametrize("value", ["nan", "inf", "-1", "0"])
def test_emos_run_refuses_a_duration_that_is_not_a_finite_positive_number(tmp_path, value):
    out = _emos_run(tmp_path, "raise SystemExit('the recipe must not run')\n", f"--duration={value}")
    assert out.returncode == 2
    assert "--duration" in out.stderr and "finite number of seconds > 0" in out.stderr


def test_emos_run_of_a_recipe_that_never_calls_bringup_fails_clearly(tmp_path):
    out = _emos_run(tmp_path, "launcher = Launcher()\nlauncher.add_pkg(components=[BaseComponent(component_name='idle')])\n")
    assert out.returncode == 5
    assert "never called Launcher.bringup()" in out.stderr
