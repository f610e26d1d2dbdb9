"""Event conditions, events and their firing rules, without processes."""
import msgpack
import numpy as np
import pytest

from emos import Event, Topic
from emos.events import Blackboard, ConditionError, EventTracker
from emos.events.conditions import evaluate
from emos.msgs import Bool, Detections, DetectionsMultiSource, Float32, String
from emos.msgs.nav import Odometry
from emos.msgs.status import ComponentStatus

pytestmark = pytest.mark.unit

battery = Topic(name="battery", msg_type="Float32", data_timeout=0.5)
mode = Topic(name="mode", msg_type="String")
bumper = Topic(name="bumper", msg_type="Bool")
dets = Topic(name="detections", msg_type="Detections")
multi = Topic(name="multi", msg_type="DetectionsMultiSource")
odom = Topic(name="odom", msg_type="Odometry", data_timeout=0.5)
status = Topic(name="planner/status", msg_type="ComponentStatus")


def detections(*labels):
    n = len(labels)
    return Detections(labels=list(labels), scores=np.ones(n), boxes=np.zeros((n, 4)))


def check(condition, messages, trigger=None):
    return evaluate(condition.to_dict()["tree"], lambda t: messages.get(t), trigger)


def test_operators_on_scalars_strings_and_lists():
    low = Float32(data=10.0)
    assert check(battery.msg.data < 20.0, {"/battery": low}) is True
    assert check(battery.msg.data >= 20.0, {"/battery": low}) is False
    assert check(battery.msg.data == 10.0, {"/battery": low}) is True
    assert check(battery.msg.data != 10.0, {"/battery": low}) is False
    assert check(battery.msg.data.is_in([1.0, 10.0]), {"/battery": low}) is True
    assert check(battery.msg.data.not_in([1.0, 10.0]), {"/battery": low}) is False
    assert check(mode.msg.data.contains("UT"), {"/mode": String(data="AUTO")}) is True
    assert check(bumper.msg.data.is_true(), {"/bumper": Bool(data=True)}) is True
    assert check(~bumper.msg.data, {"/bumper": Bool(data=True)}) is False
    assert check(bumper.msg.data.is_false(), {"/bumper": Bool(data=False)}) is True
    seen = {"/detections": detections("person", "desk")}
    assert check(dets.msg.labels.contains("person"), seen) is True
    assert check(dets.msg.labels.contains_any(["cat", "desk"]), seen) is True
    assert check(dets.msg.labels.contains_all(["desk", "window"]), seen) is False
    assert check(dets.msg.labels.not_contains_any(["cat"]), seen) is True
    assert check(dets.msg.labels.length() > 1, seen) is True
    assert check(dets.msg.labels[0] == "person", seen) is True
    assert check(dets.msg.labels[5] == "person", seen) is None  # no such element: unknown, not an error
    assert check(dets.msg.scores.contains(1.0), seen) is True


def test_nested_fields_and_fields_of_message_lists_flatten():
    o = Odometry()
    o.twist.twist.linear.x = 0.3
    assert check(odom.msg.twist.twist.linear.x > 0.1, {"/odom": o}) is True
    m = DetectionsMultiSource(detections=[detections("cat"), detections("person", "desk")])
    assert check(multi.msg.detections.labels.contains_all(["cat", "desk"]), {"/multi": m}) is True
    assert check(multi.msg.detections.labels.length() == 3, {"/multi": m}) is True


def test_composition_over_many_topics_and_bare_topics():
    cond = (battery.msg.data < 20.0) & (mode.msg.data == "AUTO") | bumper.msg.data.is_true()
    msgs = {"/battery": Float32(data=5.0), "/mode": String(data="AUTO"), "/bumper": Bool(data=False)}
    assert check(cond, msgs) is True
    msgs["/mode"] = String(data="MANUAL")
    assert check(cond, msgs) is False
    # A bare Topic is true for the message being evaluated, whatever its content.
    on_command = mode & (status.msg.status == ComponentStatus.STATUS_HEALTHY)
    msgs = {"/mode": String(data="x"), "/planner/status": ComponentStatus(status=0)}
    assert check(on_command, msgs, trigger="/mode") is True
    assert check(on_command, msgs, trigger="/planner/status") is False
    assert check((status.msg.status == 0) & mode, msgs, trigger="/mode") is True


def test_condition_is_plain_data():
    cond = ((battery.msg.data < 20.0) & ~bumper.msg.data) | dets.msg.labels.contains_any(["person"]) | mode
    data = cond.to_dict()
    assert msgpack.unpackb(msgpack.packb(data, use_bin_type=True), raw=False) == data
    assert data["topics"]["/battery"] == {"msg_type": "std_msgs/msg/Float32", "data_timeout": 0.5}


@pytest.mark.parametrize("build, words", [
    (lambda: battery.msg.dta < 3, ["/battery", "dta", "Float32", "data"]),
    (lambda: odom.msg.twist.twist.linear.w > 0, ["/odom", "linear", "Vector3", "'w'"]),
    (lambda: mode.msg.data < 3, ["/mode", "str"]),
    (lambda: battery.msg.data == "low", ["/battery", "number"]),
    (lambda: dets.msg.labels > 2, ["/detections", "labels", "list"]),
    (lambda: battery.msg.data.contains(1.0), ["/battery", "contains"]),
    (lambda: mode.msg.data.is_true(), ["/mode", "bool"]),
    (lambda: odom.msg.twist == 1, ["/odom", "TwistWithCovariance"]),
    (lambda: battery.msg.data < mode.msg.data, ["/battery", "constant"]),
    (lambda: (battery.msg.data < 3) & 5, ["Topics", "int"]),
    (lambda: (battery.msg.data < 3) | "bumper", ["Topics", "str"]),
    (lambda: Event(battery.msg.data), ["value, not a condition"]),
    (lambda: dets.msg.labels.is_in(["a"]), ["contains_any"]),
    (lambda: bool(battery.msg.data < 3), ["& | ~"]),
])
def test_bad_conditions_fail_at_definition_naming_topic_and_field(build, words):
    with pytest.raises(ConditionError) as err:
        build()
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_event_arguments_are_checked():
    with pytest.raises(ValueError, match="keep_event_delay"):
        Event(battery, keep_event_delay=-1)
    with pytest.raises(TypeError, match="on_change"):
        Event(battery, on_change="yes")
    with pytest.raises(ConditionError, match="Event"):
        Event(42)


def tracker(event):
    board = Blackboard({n: t.data_timeout for n, t in event.topics.items()})
    return EventTracker(event.to_dict()), board


def test_stale_inputs_never_fire_even_negated():
    event = Event(~(battery.msg.data > 50.0))
    tr, board = tracker(event)
    board.put("/battery", Float32(data=10.0), at=100.0)
    assert tr.check("/battery", board, now=100.1) is True
    tr2, _ = tracker(Event(~(battery.msg.data > 50.0)))
    assert tr2.check("/battery", board, now=100.6) is False  # older than data_timeout 0.5 s
    # OR with a stale branch can still be true through a fresh branch, AND cannot.
    either = Event((battery.msg.data < 20.0) | bumper.msg.data.is_true())
    tr3, board3 = tracker(either)
    board3.put("/battery", Float32(data=10.0), at=0.0)
    board3.put("/bumper", Bool(data=False), at=100.0)
    assert tr3.check("/bumper", board3, now=100.0) is False
    board3.put("/bumper", Bool(data=True), at=100.0)
    assert tr3.check("/bumper", board3, now=100.0) is True


def test_on_change_handle_once_and_keep_event_delay():
    tr, board = tracker(Event(battery.msg.data < 20.0, on_change=True))
    fired = []
    for t, v in enumerate([30, 10, 10, 30, 10]):
        board.put("/battery", Float32(data=v), at=float(t))
        fired.append(tr.check("/battery", board, now=float(t)))
    assert fired == [False, True, False, False, True]

    tr, board = tracker(Event(battery.msg.data < 20.0, handle_once=True))
    results = []
    for t in range(3):
        board.put("/battery", Float32(data=1.0), at=float(t))
        results.append(tr.check("/battery", board, now=float(t)))
    assert results == [True, False, False]
    assert EventTracker(Event(battery.msg.data < 20.0, handle_once=True).to_dict(), fired_before=True).check("/battery", board, now=2.0) is False

    tr, board = tracker(Event(battery, keep_event_delay=1.0))
    results = []
    for t in (0.0, 0.5, 0.99, 1.0, 1.5, 2.1):
        board.put("/battery", Float32(data=1.0), at=t)
        results.append(tr.check("/battery", board, now=t))
    assert results == [True, False, False, True, False, True]


def test_on_change_edges_are_over_known_values_a_stale_input_does_not_rearm():
    tr, board = tracker(Event(battery.msg.data < 20.0, on_change=True))  # data_timeout 0.5 s
    fired = []
    for at, now, v in [(0.0, 0.0, 10), (0.0, 1.0, 10), (1.1, 1.1, 10), (1.2, 1.2, 30), (1.3, 1.3, 10)]:
        board.put("/battery", Float32(data=v), at=at)
        fired.append(tr.check("/battery", board, now=now))
    # true, unknown (stale), true again: one firing; then a known false re-arms it
    assert fired == [True, False, False, False, True]


def test_bare_topic_on_change_compares_content_not_stamps():
    terrain = Topic(name="terrain", msg_type="String")
    tr, board = tracker(Event(terrain, on_change=True))
    out = []
    for t, v in enumerate(["sand", "sand", "stairs", "stairs", "sand"]):
        board.put("/terrain", String(data=v), at=float(t))
        out.append(tr.check("/terrain", board, now=float(t)))
    assert out == [True, False, True, False, True]


def test_compiled_conditions_agree_with_the_reference_evaluator():
    from emos.events.conditions import compile_condition

    conditions = [
        battery.msg.data < 20.0, battery.msg.data.is_in([1.0, 10.0]), ~bumper.msg.data, mode.msg.data.contains("UT"),
        dets.msg.labels.contains_all(["person", "desk"]), dets.msg.labels[1] == "desk", dets.msg.labels.length() >= 2,
        multi.msg.detections.labels.not_contains_any(["cat"]), odom.msg.twist.twist.linear.x > 0.1,
        ((battery.msg.data < 20.0) & ~bumper.msg.data) | mode, mode & (battery.msg.data >= 10.0), ~(dets.msg.scores.contains(1.0)),
    ]
    o = Odometry()
    o.twist.twist.linear.x = 0.3
    worlds = [
        {},
        {"/battery": Float32(data=10.0), "/bumper": Bool(data=False), "/mode": String(data="AUTO"), "/detections": detections("person", "desk"),
         "/multi": DetectionsMultiSource(detections=[detections("cat")]), "/odom": o},
        {"/battery": Float32(data=30.0), "/bumper": Bool(data=True), "/detections": detections()},
    ]
    from emos.events.compiled import compile_group

    trees = [cond.to_dict()["tree"] for cond in conditions]
    group = compile_group(trees)  # the Monitor's per-topic form: every condition in one call
    for cond, tree in zip(conditions, trees):
        fast = compile_condition(tree)
        for world in worlds:
            for trigger in (None, "/mode", "/battery"):
                assert fast(world.get, trigger) == evaluate(tree, world.get, trigger), (cond, world.keys(), trigger)
    for world in worlds:
        for trigger in (None, "/mode", "/battery"):
            assert list(group(world.get, trigger)) == [evaluate(t, world.get, trigger) for t in trees], (world.keys(), trigger)


def test_a_condition_too_wide_to_compile_is_still_evaluated():
    from functools import reduce

    from emos.events.conditions import compile_condition

    wide = reduce(lambda a, b: a | b, [battery.msg.data == float(k) for k in range(150)])  # 150 nested blocks
    tree = wide.to_dict()["tree"]
    fn = compile_condition(tree)
    from emos.events.compiled import compile_group

    group = compile_group([tree, (battery.msg.data > 100.0).to_dict()["tree"]])  # in a group, it falls back alone
    for value in (7.0, 500.0):
        world = {"/battery": Float32(data=value)}
        assert fn(world.get, "/battery") == evaluate(tree, world.get, "/battery") == (value < 150)
        assert group(world.get, "/battery") == (value < 150, value > 100.0)
