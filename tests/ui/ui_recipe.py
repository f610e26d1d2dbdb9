"""The recipe the browser tests drive: a camera, a map with odometry, and a recorder of inputs.

Environment: EMOS_UI_TEST_PORT (the page's port), EMOS_UI_TEST_OUT (a JSON-lines file the
recorder appends every message it receives from the page to).
"""
import json
import os
import time

import numpy as np

from emos import BaseComponent, Launcher, Topic
from emos.msgs import Float32, Image, MapMetaData, OccupancyGrid, Odometry, PoseStamped, StreamingString, String
from emos.msgs.std import Header, Time

OUT = os.environ["EMOS_UI_TEST_OUT"]
PORT = int(os.environ["EMOS_UI_TEST_PORT"])

camera = Topic(name="camera", msg_type="Image")
grid = Topic(name="map", msg_type="OccupancyGrid")
odom = Topic(name="odom", msg_type="Odometry")
question = Topic(name="question", msg_type="String")
answer = Topic(name="answer", msg_type="String")
reply = Topic(name="reply", msg_type="StreamingString")
goal = Topic(name="goal", msg_type="PoseStamped")
estop = Topic(name="estop", msg_type="Bool")
voice = Topic(name="voice", msg_type="Audio")

RES, W, H = 0.05, 200, 160  # 10 m x 8 m; origin (-2, -1)


class Camera(BaseComponent):
    def _execution_step(self):
        frame = np.zeros((120, 160, 3), np.uint8)
        frame[..., 0], frame[..., 1] = 200, 40  # a red picture: the test looks for it on the canvas
        self.publish(camera, Image.from_numpy(frame, header=Header(stamp=Time.now())))
        self.health_status.set_healthy()


class World(BaseComponent):
    def _execution_step(self):
        cells = np.zeros((H, W), np.int8)
        cells[0, :] = cells[-1, :] = 100
        info = MapMetaData(resolution=RES, width=W, height=H)
        info.origin.position.x, info.origin.position.y = -2.0, -1.0
        self.publish(grid, OccupancyGrid(header=Header(stamp=Time.now(), frame_id="map"), info=info, data=cells.reshape(-1)))
        msg = Odometry(header=Header(stamp=Time.now(), frame_id="map"))
        msg.pose.pose.position.x = 1.0
        self.publish(odom, msg)
        self.health_status.set_healthy()


class Recorder(BaseComponent):
    """Writes what the page sent, and answers questions."""

    def _execution_step(self, msg=None, topic=None):
        if msg is not None:
            if topic.name == "/goal":
                value = [msg.pose.position.x, msg.pose.position.y, msg.header.frame_id]
            elif topic.name == "/voice":
                value = len(msg.data)
            else:
                value = msg.data
            with open(OUT, "a") as f:
                f.write(json.dumps({"topic": topic.name, "value": value, "t": time.time()}) + "\n")
            if topic.name == "/question":
                self.publish(answer, String(data=f"echo: {msg.data}"))
                words = ["streamed", "reply", "to", msg.data]
                for i, word in enumerate(words):  # as an LLM streams its tokens
                    self.publish(reply, StreamingString(stream=True, done=i == len(words) - 1, data=word + " "))
        self.health_status.set_healthy()


class Navigator(BaseComponent):
    """An action server: goal a pose, feedback the distance left, result a sentence."""

    main_action_type = (PoseStamped, Float32, String)

    def _main_action_callback(self, goal_handle):
        p = goal_handle.goal.pose.position
        for left in (2.0, 1.0):
            goal_handle.publish_feedback(Float32(data=left))
            time.sleep(0.05)
        with open(OUT, "a") as f:
            f.write(json.dumps({"topic": "navigate", "value": [p.x, p.y], "t": time.time()}) + "\n")
        return String(data=f"reached {p.x:.2f} {p.y:.2f}")


navigator = Navigator(component_name="navigator", run_type="ActionServer")
cam = Camera(component_name="camera", outputs=[camera], trigger=1 / 30)
world = World(component_name="world", outputs=[grid, odom], trigger=0.5)
recorder = Recorder(component_name="recorder", inputs=[question, goal, estop, voice], outputs=[answer, reply], trigger=[question, goal, estop, voice])

launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[cam, world, recorder, navigator])
launcher.enable_ui(inputs=[question, goal, estop, voice, navigator.ui_main_action_input], outputs=[camera, grid, odom, answer, reply], port=PORT)
launcher.bringup()
