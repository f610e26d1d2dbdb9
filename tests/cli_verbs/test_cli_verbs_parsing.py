"""Issue 33 D4 and item 4, without processes: every verb group takes its shared options before
or after the verb; a component's description of its services is read defensively, and a type
module it names is imported only from the emos package."""
from __future__ import annotations

import argparse
import sys

import pytest

from emos.core.services import describe_interfaces
from emos.tools.cli import action, component, service, topic
from emos.tools.cli.interfaces import InterfaceError, _parse

pytestmark = pytest.mark.unit


def parse(module, argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="emos x")
    module.add_arguments(parser)
    return parser.parse_args(argv)


@pytest.mark.parametrize("argv", [
    ["info", "--run", "R1", "planner"],
    ["--run", "R1", "info", "planner"],
    ["info", "planner", "--run", "R1"],
])
def test_component_run_option_goes_anywhere(argv):
    args = parse(component, argv)
    assert (args.verb, args.name, args.run, args.timeout) == ("info", "planner", "R1", 15.0)


def test_component_call_keeps_its_parameters_with_options_anywhere():
    args = parse(component, ["--timeout", "3", "call", "c", "update_config_parameter", "name=loop_rate", "value=5", "--run", "R"])
    assert (args.name, args.service, args.params, args.run, args.timeout) == \
        ("c", "update_config_parameter", ["name=loop_rate", "value=5"], "R", 3.0)
    assert parse(component, ["list"]).run is None  # left out: the group's default, not SUPPRESS


@pytest.mark.parametrize("argv", [["--run", "R", "echo", "/scan"], ["echo", "/scan", "--run", "R"], ["echo", "--run", "R", "/scan"]])
def test_topic_run_option_goes_anywhere(argv):
    args = parse(topic, argv)
    assert (args.action, args.topic, args.run) == ("echo", "/scan", "R")


def test_service_unit_options_and_call_options_go_anywhere():
    for argv in (["--print", "create", "ui_demo"], ["create", "ui_demo", "--print"]):
        args = parse(service, argv)
        assert (args.action, args.recipe, args.print, args.restart_time) == ("create", "ui_demo", True, "3s")
    args = parse(service, ["--run", "R", "call", "planner", "save_plan_to_file", '{"file_name": "p.csv"}', "--timeout", "5"])
    assert (args.component, args.service, args.request, args.run, args.timeout) == \
        ("planner", "save_plan_to_file", '{"file_name": "p.csv"}', "R", 5.0)
    assert parse(service, ["list"]).component is None
    with pytest.raises(SystemExit):  # a verb that is not one stays a usage error
        parse(service, ["bogus", "x"])


def test_action_options_go_anywhere_and_times_are_checked(capsys):
    for argv in (["--run", "R", "send_goal", "c", "a", "{}"], ["send_goal", "c", "a", "{}", "--run", "R"]):
        args = parse(action, argv)
        assert (args.verb, args.component, args.action, args.goal, args.run, args.timeout) == ("send_goal", "c", "a", "{}", "R", 0.0)
    for bad in (["--timeout", "-1"], ["--timeout", "nan"], ["--cancel-timeout", "0"]):
        with pytest.raises(SystemExit):
            parse(action, ["send_goal", "c", "a", *bad])
        assert "must be a finite number of seconds" in capsys.readouterr().err


def test_a_components_description_is_read_defensively_and_names_only_emos_modules():
    from emos.msgs import Bool, SetBoolRequest, SetBoolResponse, String

    described = describe_interfaces([("service", "c/set", (SetBoolRequest, SetBoolResponse)),
                                     ("action", "c/act", ("String", Bool, "NoSuchType"))], serving={"c/set"})
    assert described["services"][0]["request"] == {"type": "std_srvs/msg/SetBool_Request", "module": "emos.msgs.srv"}
    assert described["services"][0]["serving"] is True and described["actions"][0]["serving"] is False
    assert described["actions"][0]["result"] == {"type": "NoSuchType", "module": ""}
    assert described["actions"][0]["goal"]["module"] == String.__module__
    found = _parse("c", "service", described["services"] + ["junk", {"name": 3}, {"name": "c/x", "request": {"type": "String"}}])
    assert [i.name for i in found] == ["c/set"]  # entries without a name or all their types are skipped
    assert found[0].message_class("request") is SetBoolRequest
    # A type from a module outside the emos package is never imported on the component's word.
    planted = _parse("c", "service", [{"name": "c/y", "request": {"type": "evil/msg/X", "module": "os.path"},
                                       "response": {"type": "evil/msg/Y", "module": "antigravity"}}])[0]
    with pytest.raises(InterfaceError, match="outside the emos package.*--import MODULE"):
        planted.message_class("response")
    assert "antigravity" not in sys.modules
