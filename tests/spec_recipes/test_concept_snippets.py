"""The code of the concept pages that defines events and actions but launches nothing
(concepts/events-and-actions.md, concepts/status-and-fallbacks.md, concepts/components.md),
run as the pages give it with the imports changed (and the errata's fixes), checked against
what each page says it does. No processes: the conditions are evaluated on messages, the
actions' topic bindings resolved as the Monitor resolves them when an event fires."""
import logging

import pytest

from emos import Action, BaseComponent, ComponentRunType, Event, Topic, component_fallback
from emos.actions import log, restart
from emos.events import Blackboard, EventTracker
from emos.events.action import resolve_bindings
from emos.msgs import Bool, Float32, String
from emos.msgs.nav import Pose

pytestmark = pytest.mark.unit


def fires(event: Event, messages: dict, trigger: str, now: float = 100.0) -> bool:
    """One check of a fresh event (as the Monitor makes it) when ``trigger`` brings a message."""
    board = Blackboard({n: t.data_timeout for n, t in event.topics.items()})
    for name, (msg, at) in messages.items():
        board.put(name, msg, at=at)
    return EventTracker(event.to_dict()).check(trigger, board, now=now)


def test_basic_single_topic_event_fires_below_20_percent_and_never_on_stale_data():
    battery = Topic(name="/battery_level", msg_type="Float32", data_timeout=0.5)
    low_batt_event = Event(battery.msg.data < 20.0)
    assert fires(low_batt_event, {"/battery_level": (Float32(data=15.0), 100.0)}, "/battery_level") is True
    assert fires(low_batt_event, {"/battery_level": (Float32(data=50.0), 100.0)}, "/battery_level") is False
    # "stale after 0.5s"
    assert fires(low_batt_event, {"/battery_level": (Float32(data=15.0), 99.0)}, "/battery_level") is False


def test_composed_multi_topic_condition_needs_both_topics():
    lidar_topic = Topic(name="/person_detected", msg_type="Bool", data_timeout=0.5)
    status_topic = Topic(name="/robot_mode", msg_type="String", data_timeout=60.0)
    emergency_stop_event = Event((lidar_topic.msg.data.is_true()) & (status_topic.msg.data == "AUTO"))
    auto = (String(data="AUTO"), 90.0)
    assert fires(emergency_stop_event, {"/person_detected": (Bool(data=True), 100.0), "/robot_mode": auto}, "/person_detected")
    assert not fires(emergency_stop_event, {"/person_detected": (Bool(data=True), 100.0),
                                            "/robot_mode": (String(data="MANUAL"), 90.0)}, "/person_detected")
    assert not fires(emergency_stop_event, {"/person_detected": (Bool(data=False), 100.0), "/robot_mode": auto}, "/person_detected")


def test_drone_safety_stops_on_proximity_or_bumper_and_returns_when_low_and_far():
    proximity_sensor = Topic(name="/radar_front", msg_type="Float32", data_timeout=0.2)
    bumper = Topic(name="/bumper", msg_type="Bool", data_timeout=0.1)
    battery = Topic(name="/battery", msg_type="Float32")
    location = Topic(name="/pose", msg_type="Pose")
    is_danger = (proximity_sensor.msg.data < 0.2) | (bumper.msg.data.is_true())
    with pytest.raises(AttributeError):  # the page's `location.position.z` (errata: a Topic has no position)
        location.position.z  # noqa: B018
    needs_return = (battery.msg.data < 20.0) & (location.msg.position.z > 100.0)  # errata: .msg
    safety_event = Event(is_danger)
    return_event = Event(needs_return, on_change=True)

    far = Pose()
    far.position.z = 150.0
    near = Pose()
    near.position.z = 10.0
    assert fires(safety_event, {"/radar_front": (Float32(data=0.1), 100.0), "/bumper": (Bool(data=False), 100.0)}, "/radar_front")
    assert fires(safety_event, {"/radar_front": (Float32(data=5.0), 100.0), "/bumper": (Bool(data=True), 100.0)}, "/bumper")
    assert not fires(safety_event, {"/radar_front": (Float32(data=5.0), 100.0), "/bumper": (Bool(data=False), 100.0)}, "/bumper")
    assert fires(return_event, {"/battery": (Float32(data=15.0), 100.0), "/pose": (far, 100.0)}, "/battery")
    assert not fires(return_event, {"/battery": (Float32(data=15.0), 100.0), "/pose": (near, 100.0)}, "/battery")


def test_basic_actions_wrap_component_methods_with_kwargs_and_plain_functions():
    def custom_routine():
        logging.info("I am executing an action!")  # noqa: LOG015 - the page's code

    with pytest.raises(TypeError):  # the page's node_name= (errata: component_name=)
        BaseComponent(node_name='test_component')
    my_component = BaseComponent(component_name='test_component')
    action1 = Action(method=my_component.start)
    action2 = Action(method=my_component.update_parameter, kwargs={"param_name": "fallback_rate", "new_value": 1000})
    action3 = Action(method=custom_routine)
    assert action1.method_name == "start" and action2.method_name == "update_parameter"
    assert action2.kwargs == {"param_name": "fallback_rate", "new_value": 1000}
    assert action3.method_name.endswith("custom_routine")


def test_dynamic_data_injection_passes_the_other_topics_values_when_the_alarm_fires():
    topic_1 = Topic(name="system_alarm", msg_type="Bool")
    topic_2 = Topic(name="robot_mode", msg_type="String")
    topic_3 = Topic(name="battery_voltage", msg_type="Float32")
    event_on_first_topic = Event(topic_1.msg.data.is_true())
    printed = []

    def log_context_message(mode, voltage):
        printed.append(f"System Alarm! Current Mode: {mode}, Voltage: {voltage}V")

    my_action = Action(method=log_context_message, args=(topic_2.msg.data, topic_3.msg.data))
    latest = {"/system_alarm": Bool(data=True), "/robot_mode": String(data="AUTO"), "/battery_voltage": Float32(data=24.5)}
    assert fires(event_on_first_topic, {"/system_alarm": (latest["/system_alarm"], 100.0)}, "/system_alarm")
    log_context_message(*resolve_bindings(my_action.args, latest.get))
    assert printed == ["System Alarm! Current Mode: AUTO, Voltage: 24.5V"]


def test_status_and_fallbacks_snippets_register_their_ladders():
    lidar = BaseComponent(component_name='lidar_driver')
    lidar.on_component_fail(fallback=restart(component=lidar))
    lidar.on_system_fail(fallback=log(msg="Waiting for Lidar data..."))
    lidar.on_giveup(fallback=log(msg="LIDAR IS DEAD. STOPPING ROBOT."))
    assert set(lidar.fallbacks) >= {"on_component_fail", "on_system_fail", "on_giveup"}

    class MyDriver(BaseComponent):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            # Register the custom fallback internally
            self.on_system_fail(fallback=Action(self.try_reconnect), max_retries=3)

        @component_fallback
        def try_reconnect(self) -> bool:
            """Custom recovery logic"""
            return True

    driver = MyDriver(component_name="my_driver")
    assert driver.fallbacks["on_system_fail"].max_retries == 3


def test_components_page_run_type_and_declared_topics():
    comp = BaseComponent(component_name='test')
    comp.run_type = ComponentRunType.TIMED
    comp.run_type = "Event"
    assert comp.run_type == ComponentRunType.EVENT
    # The page's `comp.run_type = "Server"` on a bare BaseComponent: it has no main service to
    # serve, which is said at definition, naming the component.
    with pytest.raises(ValueError, match="'test'.*main_srv_type"):
        comp.run_type = "Server"
    map_topic = Topic(name="map", msg_type="OccupancyGrid")
    voice_topic = Topic(name="voice_cmd", msg_type="Audio")
    image_topic = Topic(name="camera/rgb", msg_type="Image")
    comp = BaseComponent(component_name='audio_processor', inputs=[map_topic, image_topic], outputs=[voice_topic])
    assert [t.name for t in comp.in_topics] == ["/map", "/camera/rgb"] and [t.name for t in comp.out_topics] == ["/voice_cmd"]
