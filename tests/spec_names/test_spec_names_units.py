"""The names the spec's recipes import (issue 33 item 1), in one process: ``ServiceClientConfig``,
the ``PathFromToFile`` / ``StartPathRecording`` service types, ``ComponentFallbacks``, and the
event classes ``OnGreater``, ``OnLess`` (and their siblings) of the events module.

Definition-time errors name the thing; the event classes fire as the original's (level: on each
message that passes; ``on_change`` and ``keep_event_delay`` as for any Event); service calls go
over a real service socket of a private run."""
from __future__ import annotations

import asyncio
import threading
from collections.abc import Iterator

import numpy as np
import pytest

from emos import msgs as M
from emos.events.event import Blackboard, EventTracker
from emos.io.topic import Topic

pytestmark = pytest.mark.unit


# ============================================================================ the spec's imports
def test_the_spec_imports_port_by_changing_the_module_only():
    # from kompass.ros import Topic, Launcher, ServiceClientConfig
    # from ros_sugar.core import ComponentFallbacks, BaseComponent
    # from ros_sugar.events import OnLess ; from kompass import event ; event.OnGreater(...)
    from emos import ComponentFallbacks, Launcher, ServiceClientConfig  # noqa: F401
    from emos import events as event
    from emos.actors.nav.components.interfaces import PathFromToFile, StartPathRecording
    from emos.core import BaseComponent  # noqa: F401
    from emos.core import ComponentFallbacks as CoreFallbacks
    from emos.events import OnGreater, OnLess

    assert event.OnGreater is OnGreater and event.OnLess is OnLess and CoreFallbacks is ComponentFallbacks
    assert PathFromToFile.Request is M.resolve("kompass_interfaces/PathFromToFile_Request")
    assert StartPathRecording.Request().recording_time_step == pytest.approx(0.1)


# ============================================================================ events
POINT = Topic(name="/clicked_point", msg_type="PointStamped")
BATTERY = Topic(name="/battery", msg_type="Float32")
LABELS = Topic(name="/labels", msg_type="Detections")


def _click(sec: int) -> M.PointStamped:
    return M.PointStamped(header=M.Header(stamp=M.Time(sec=sec), frame_id="map"), point=M.Point(x=1.0, y=2.0))


def _fires(event, topic: Topic, messages, times=None) -> list[bool]:
    """Whether ``event`` fires on each message in turn (the Monitor's tracker, as in a run)."""
    tracker = EventTracker(event.to_dict())
    board = Blackboard({topic.name: topic.data_timeout})
    out = []
    for i, msg in enumerate(messages):
        now = float(i) if times is None else times[i]
        board.put(topic.name, msg, at=now)
        out.append(tracker.check(topic.name, board, now=now))
    return out


def test_on_greater_fires_on_every_click_as_the_cross_component_page_needs():
    from emos import Event
    from emos import events as event

    on_click = event.OnGreater("rviz_goal", POINT, 0, ["header", "stamp", "sec"])
    # Every new clicked point has a stamp > 0: each fires (not only the first, as an edge would).
    assert _fires(on_click, POINT, [_click(0), _click(5), _click(6), _click(7)]) == [False, True, True, True]
    assert on_click.name == on_click.event_name == "rviz_goal"
    # The same condition the port wrote by hand: Event(clicked_point.msg.header.stamp.sec > 0)
    assert on_click.to_dict()["condition"] == Event(POINT.msg.header.stamp.sec > 0).to_dict()["condition"]


def test_on_greater_and_on_less_thresholds_or_equal_and_crossing():
    from emos.events import OnGreater, OnLess

    levels = [M.Float32(data=v) for v in (30.0, 15.0, 10.0, 15.0, 20.0, 12.0)]
    assert _fires(OnLess("low", BATTERY, 15.0, "data"), BATTERY, levels) == [False, False, True, False, False, True]
    assert _fires(OnLess("low", BATTERY, 15.0, ["data"], or_equal=True), BATTERY, levels) == [False, True, True, True, False, True]
    assert _fires(OnGreater("high", BATTERY, 15.0, "data"), BATTERY, levels) == [True, False, False, False, True, False]
    assert _fires(OnGreater("high", BATTERY, 15.0, "data", True), BATTERY, levels) == [True, True, False, True, True, False]
    # on_change (an EMOS option): only when the value crosses below, again after it went back up
    assert _fires(OnLess("low", BATTERY, 16.0, "data", on_change=True), BATTERY, levels) == [False, True, False, False, False, True]
    # keep_event_delay: at most once per 10 s of the Monitor's clock
    assert _fires(OnLess("low", BATTERY, 25.0, "data", keep_event_delay=10.0), BATTERY, levels,
                  times=[0.0, 1.0, 2.0, 12.0, 13.0, 14.0]) == [False, True, False, True, False, False]


def test_equal_different_contains_and_any():
    from emos.events import OnAny, OnContainsAll, OnContainsAny, OnDifferent, OnEqual

    values = [M.Float32(data=v) for v in (1.0, 2.0, 2.0)]
    assert _fires(OnEqual("two", BATTERY, 2.0, "data"), BATTERY, values) == [False, True, True]
    assert _fires(OnDifferent("not_two", BATTERY, 2.0, "data"), BATTERY, values) == [True, False, False]
    assert _fires(OnAny("any", BATTERY), BATTERY, values) == [True, True, True]
    seen = [M.Detections(labels=labels, scores=[0.9] * len(labels), boxes=np.zeros((len(labels), 4)))
            for labels in (["cup"], ["person", "cup"], [])]
    assert _fires(OnContainsAny("someone", LABELS, ["person", "dog"], "labels"), LABELS, seen) == [False, True, False]
    assert _fires(OnContainsAll("both", LABELS, ["person", "cup"], "labels"), LABELS, seen) == [False, True, False]
    assert _fires(OnContainsAny("a_cup", LABELS, "cup", "labels"), LABELS, seen) == [True, True, False]


@pytest.mark.parametrize("make, words", [
    (lambda E: E.OnGreater("g", POINT, 0, ["header", "stamp", "secs"]), ["OnGreater('g')", "'/clicked_point'", "'secs'", "Time", "sec"]),
    (lambda E: E.OnGreater("g", POINT, "zero", ["header", "stamp", "sec"]), ["compare it with a number", "'zero'"]),
    (lambda E: E.OnLess("low", BATTERY, 15.0, []), ["nested_attributes", "Float32"]),
    (lambda E: E.OnLess("low", "/battery", 15.0, "data"), ["event_source must be a Topic", "'/battery'"]),
    (lambda E: E.OnLess("", BATTERY, 15.0, "data"), ["event_name"]),
    (lambda E: E.OnLess("low", BATTERY, 15.0, "data", or_equal="yes"), ["or_equal must be a bool"]),
    (lambda E: E.OnGreater("g", POINT, 0, ["header"]), ["'>' needs a number or a str field"]),
    (lambda E: E.OnContainsAny("c", LABELS, [1.5], "labels"), ["labels", "str"]),
])
def test_event_classes_refuse_bad_definitions_naming_the_problem(make, words):
    from emos import events as E

    with pytest.raises((TypeError, ValueError)) as info:
        make(E)
    for w in words:
        assert w in str(info.value), str(info.value)


# ============================================================================ ComponentFallbacks
def _component():
    from emos import BaseComponent

    class Awesome(BaseComponent):
        def _execution_step(self) -> None:
            pass

        def reset_me(self) -> bool:
            return True

    return Awesome(component_name="awesome_component")


def test_component_fallbacks_apply_and_read_back():
    from emos import Action, ComponentFallbacks
    from emos.core.fallbacks import Fallback

    comp = _component()
    ladder = [Action(method=comp.reset_me), Action(method=comp.restart)]
    fallbacks = ComponentFallbacks(on_any_fail=Action(method=comp.restart), on_algorithm_fail=Fallback(ladder, max_retries=2),
                                   on_system_fail=ladder)
    fallbacks.apply(comp)
    have = comp.fallbacks
    assert set(have) == {"on_fail", "on_algorithm_fail", "on_system_fail"}
    assert have["on_algorithm_fail"].steps == ladder and have["on_algorithm_fail"].max_retries == 2
    assert have["on_system_fail"].is_ladder and have["on_system_fail"].per_step == 1
    assert not have["on_fail"].is_ladder and have["on_fail"].per_step is None  # one action: unlimited
    back = ComponentFallbacks.of(comp)
    assert back.on_any_fail is have["on_fail"] and back.on_component_fail is None and back.on_giveup is None
    assert "on_algorithm_fail=" in repr(back)


def test_component_fallbacks_refuse_what_is_not_an_action_at_definition():
    from emos import ComponentFallbacks

    with pytest.raises(TypeError, match=r"ComponentFallbacks\(on_system_fail=...\): fallbacks are Actions"):
        ComponentFallbacks(on_system_fail="restart")
    with pytest.raises(ValueError, match=r"ComponentFallbacks\(on_giveup=...\): the ladder is empty"):
        ComponentFallbacks(on_giveup=[])
    with pytest.raises(TypeError, match="expects a component"):
        ComponentFallbacks().apply(object())


# ============================================================================ ServiceClientConfig
def test_service_client_config_checks_name_and_type_at_definition():
    from emos import ServiceClientConfig
    from emos.actors.nav.components.interfaces import PathFromToFile, PathFromToFileRequest, PathFromToFileResponse

    ok = ServiceClientConfig(name="planner/save_plan_to_file", srv_type=PathFromToFile)
    assert (ok.request_type, ok.response_type) == (PathFromToFileRequest, PathFromToFileResponse)
    assert ok.timeout_secs == 30.0 and ok.attempt_period_secs == 1.0  # the original's defaults
    pair = ServiceClientConfig(name="/planner/x", srv_type=("kompass_interfaces/PathFromToFile_Request", PathFromToFileResponse))
    assert pair.request_type is PathFromToFileRequest
    with pytest.raises(TypeError, match=r"ServiceClientConfig\(name='planner/save_plan_to_file'\): srv_type must be a service type "
                                        r"with \.Request and \.Response"):
        ServiceClientConfig(name="planner/save_plan_to_file", srv_type=PathFromToFileRequest)
    with pytest.raises(TypeError, match="must be EMOS message types"):
        ServiceClientConfig(name="planner/x", srv_type=("NoSuchRequest", "NoSuchResponse"))
    for bad in ("", "planner save", "planner//save", 3):
        with pytest.raises(ValueError, match="ServiceClientConfig: name must be a service name"):
            ServiceClientConfig(name=bad, srv_type=PathFromToFile)
    with pytest.raises(ValueError, match="timeout_secs must be a number > 0"):
        ServiceClientConfig(name="planner/x", srv_type=PathFromToFile, timeout_secs=0)
    with pytest.raises(ValueError, match="ServiceClientConfig: name must be"):
        ok.name = "bad name"  # checked on assignment too
    with pytest.raises(TypeError, match=r"service 'planner/save_plan_to_file': cannot build a PathFromToFileRequest .*file_location, file_name"):
        ok.request(file="x.csv")
    with pytest.raises(TypeError, match="takes PathFromToFileRequest, got StartPathRecordingRequest"):
        ok.send_request(M.resolve("kompass_interfaces/StartPathRecording_Request")())


def test_service_client_config_as_event_actions():
    from emos import ServiceClientConfig
    from emos.actors.nav.components.interfaces import PathFromToFile

    srv = ServiceClientConfig(name="planner/load_plan_from_file", srv_type=PathFromToFile)
    send = srv.send_request(file_location="/tmp", file_name="golden.csv")
    assert send.predefined == "send_srv_request" and send.kwargs["srv_name"] == "planner/load_plan_from_file"
    assert send.kwargs["request"].file_name == "golden.csv"
    assert srv.trigger().predefined == "trigger_service"


@pytest.fixture
def served() -> Iterator[tuple]:
    """A private run with ``planner/save_plan_to_file`` served from a real socket; the requests it got."""
    from emos.actors.nav.components.interfaces import PathFromToFileRequest, PathFromToFileResponse
    from emos.core.services import ServiceServer
    from emos.transport.context import RunContext

    ctx = RunContext.create()
    got: list = []

    def save(req: PathFromToFileRequest) -> PathFromToFileResponse:
        got.append(req)
        return PathFromToFileResponse(success=bool(req.file_name), message=f"saved {req.file_location}/{req.file_name}")

    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    server = ServiceServer(ctx, "planner/save_plan_to_file", PathFromToFileRequest, PathFromToFileResponse, save, owner="planner")
    asyncio.run_coroutine_threadsafe(server.start(), loop).result(30)
    try:
        yield ctx, got, loop
    finally:
        asyncio.run_coroutine_threadsafe(server.close(), loop).result(30)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(30)
        loop.close()
        ctx.remove_everything()


def test_service_client_config_calls_the_service(served):
    from emos import ServiceClientConfig
    from emos.actors.nav.components.interfaces import PathFromToFile
    from emos.errors import TransportError

    ctx, got, _ = served
    srv = ServiceClientConfig(name="/planner/save_plan_to_file", srv_type=PathFromToFile)  # '/' or not: the same service
    answer = srv.call(file_location="/tmp/", file_name="computed_path.csv", ctx=ctx)
    assert answer.success and answer.message == "saved /tmp//computed_path.csv"
    assert srv.call(PathFromToFile.Request(file_location="/tmp"), ctx=ctx).success is False
    assert [r.file_name for r in got] == ["computed_path.csv", ""]
    missing = ServiceClientConfig(name="planner/load_plan_from_file", srv_type=PathFromToFile, timeout_secs=0.3, attempt_period_secs=0.1)
    with pytest.raises(TransportError, match=r"service 'planner/load_plan_from_file' \(PathFromToFileRequest\) did not answer within 0.3 s"):
        missing.call(file_name="x.csv", ctx=ctx)


def test_the_ui_calls_a_service_from_its_form(served):
    """The UI's service runner (actors/ui/services.py): the form of the request's fields, the call,
    the response sent back to the page; bad input and unknown names refused with a sentence."""
    from emos import ServiceClientConfig
    from emos.actors.nav.components.interfaces import PathFromToFile
    from emos.actors.ui.actions import ActionRunner
    from emos.actors.ui.services import InputRunners, with_services
    from emos.core.services import service_socket

    ctx, got, loop = served
    srv = ServiceClientConfig(name="planner/save_plan_to_file", srv_type=PathFromToFile)
    socket_of = lambda name: service_socket(ctx, name)  # noqa: E731
    assert isinstance(with_services(ActionRunner({}, socket_of), {}, socket_of), ActionRunner)  # no services: as before
    runners = with_services(ActionRunner({}, socket_of), {srv.name: srv}, socket_of)
    assert isinstance(runners, InputRunners)
    (card,) = runners.describe()
    assert card["topic"] == "planner/save_plan_to_file" and card["service"] and card["component"] == "planner"
    assert [f["name"] for f in card["fields"]] == ["file_location", "file_name"]

    async def page(value) -> tuple[dict, list[dict]]:
        sent: list[dict] = []
        done = asyncio.Event()

        async def reply(m: dict) -> None:
            sent.append(m)
            if m["state"] != "sent":
                done.set()

        first = runners.send({"op": "goal", "id": 1, "topic": "planner/save_plan_to_file", "value": value}, reply)
        if first["ok"]:
            await asyncio.wait_for(done.wait(), 30)
        return first, sent

    first, sent = asyncio.run_coroutine_threadsafe(page({"file_location": "/tmp/", "file_name": "a.csv"}), loop).result(60)
    assert first["ok"] and [m["state"] for m in sent] == ["sent", "succeeded"]
    assert sent[-1]["value"] == {"success": True, "message": "saved /tmp//a.csv"} and got[-1].file_name == "a.csv"
    _, sent = asyncio.run_coroutine_threadsafe(page({"file_location": "/tmp/"}), loop).result(60)
    assert sent[-1]["state"] == "failed" and sent[-1]["value"]["success"] is False  # the service said no
    refused, _ = asyncio.run_coroutine_threadsafe(page({"file": 3}), loop).result(60)
    assert not refused["ok"] and "planner/save_plan_to_file" in refused["error"]
    assert not runners.cancel({"id": 2, "topic": "planner/save_plan_to_file"})["ok"]
    unknown = runners.send({"op": "goal", "id": 3, "topic": "planner/nope", "value": {}}, None)  # not a service: the actions say no
    assert not unknown["ok"] and "'planner/nope' is not an action of this page" in unknown["error"]
    runners.close()
