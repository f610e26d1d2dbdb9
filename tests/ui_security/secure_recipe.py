"""The recipe the UI security tests drive: a talker, a recorder of every input, an action server,
a service, and an event, with the UI served as the test's environment says.

Environment: EMOS_UI_TEST_PORT, EMOS_UI_TEST_OUT (JSON lines of what the recorder received),
EMOS_UI_TEST_HEADLESS=1 for enable_ui(serve_browser=False); EMOS_UI_TEST_ZONES_MAP=MAP.yaml adds a
component publishing that map on /map and the zone editor for it. HTTPS comes from `emos run --ui-https`.
"""
import json
import os
import time

from emos import Action, BaseComponent, Event, Launcher, Topic
from emos.core.service_config import ServiceClientConfig
from emos.msgs import Float32, PoseStamped, SetBoolRequest, SetBoolResponse, String

OUT = os.environ["EMOS_UI_TEST_OUT"]
PORT = int(os.environ["EMOS_UI_TEST_PORT"])

words = Topic(name="words", msg_type="String")
question = Topic(name="question", msg_type="String")
speed = Topic(name="speed", msg_type="Float32")
estop = Topic(name="estop", msg_type="Bool")
cmd = Topic(name="cmd", msg_type="Twist")
goal = Topic(name="goal", msg_type="PoseStamped")


def record(topic, value):
    with open(OUT, "a") as f:
        f.write(json.dumps({"topic": topic, "value": value, "t": time.time()}) + "\n")


class Talker(BaseComponent):
    def _execution_step(self):
        self.publish(words, String(data="still talking"))
        self.health_status.set_healthy()


class Recorder(BaseComponent):
    def _execution_step(self, msg=None, topic=None):
        if msg is not None:
            if topic.name == "/goal":
                value = [msg.pose.position.x, msg.pose.position.y]
            elif topic.name == "/cmd":
                value = [msg.linear.x, msg.angular.z]
            else:
                value = msg.data
            record(topic.name, value)
        self.health_status.set_healthy()

    def note_estop(self):
        record("estop-event", True)


class Lamp(BaseComponent):
    def custom_on_configure(self):
        self.create_service("lamp/set", SetBoolRequest, SetBoolResponse, self._set)

    def _set(self, request):
        record("lamp/set", request.data)
        return SetBoolResponse(success=True, message=f"lamp {'on' if request.data else 'off'}")

    def _execution_step(self):
        self.health_status.set_healthy()


class Navigator(BaseComponent):
    main_action_type = (PoseStamped, Float32, String)

    def _main_action_callback(self, goal_handle):
        p = goal_handle.goal.pose.position
        for left in (3.0, 2.0, 1.0):
            goal_handle.publish_feedback(Float32(data=left))
            time.sleep(0.3 if p.x < 50 else 1.0)  # x >= 50: a long goal, for cancelling
        record("navigate", [p.x, p.y])
        return String(data=f"reached {p.x:.2f} {p.y:.2f}")


talker = Talker(component_name="talker", outputs=[words], trigger=0.2)
recorder = Recorder(component_name="recorder", inputs=[question, speed, estop, cmd, goal], trigger=[question, speed, estop, cmd, goal])
lamp = Lamp(component_name="lamp", trigger=1.0)
navigator = Navigator(component_name="navigator", run_type="ActionServer")
lamp_service = ServiceClientConfig(name="lamp/set", srv_type=(SetBoolRequest, SetBoolResponse))

ZONES_MAP = os.environ.get("EMOS_UI_TEST_ZONES_MAP", "")
grid = Topic(name="map", msg_type="OccupancyGrid")


class MapPublisher(BaseComponent):
    def _execution_step(self):
        from emos.actors.nav.maps import load_map
        from emos.msgs import Header, MapMetaData, OccupancyGrid

        m = load_map(ZONES_MAP)
        info = MapMetaData(resolution=m.resolution, width=m.width, height=m.height)
        info.origin.position.x, info.origin.position.y = m.origin[0], m.origin[1]
        self.publish(grid, OccupancyGrid(header=Header(frame_id="map"), info=info, data=m.flat_data()))
        self.health_status.set_healthy()


extra = [MapPublisher(component_name="map_publisher", outputs=[grid], trigger=1.0)] if ZONES_MAP else []
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[talker, recorder, lamp, navigator, *extra],
                 events_actions={Event(estop.msg.data == True, name="estop pressed"): Action(recorder.note_estop)})  # noqa: E712
launcher.enable_ui(inputs=[question, speed, estop, cmd, goal, navigator.ui_main_action_input, lamp_service], outputs=[words, *([grid] if ZONES_MAP else [])],
                   port=PORT, serve_browser=os.environ.get("EMOS_UI_TEST_HEADLESS") != "1", auth_failures_per_minute=30,
                   **({"zones_map": ZONES_MAP} if ZONES_MAP else {}))
launcher.bringup()
