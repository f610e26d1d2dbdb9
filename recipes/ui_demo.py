"""A recipe with a web page: a camera, a map with the robot and its plan, a chat and a battery.

    emos run ui_demo            # then open the link it prints (http://127.0.0.1:5001/?token=...)
    emos run ui_demo -- --port 5002

Everything here is synthetic so that it runs on any machine: the camera draws a moving pattern,
the robot drives a circle on a drawn floor plan, and "planning" draws a straight line from the
robot to the goal you click. Replace the components with real ones; the UI line stays the same.
"""
import argparse
import math
import time

import numpy as np

from emos import BaseComponent, Launcher, Topic
from emos.msgs import Float32, Image, MapMetaData, OccupancyGrid, Odometry, Path, Pose, PoseStamped, String
from emos.msgs.std import Header, Time

parser = argparse.ArgumentParser()
parser.add_argument("--port", type=int, default=5001)
parser.add_argument("--host", default="127.0.0.1")
options, _ = parser.parse_known_args()

camera = Topic(name="camera/rgb", msg_type="Image")
grid = Topic(name="map", msg_type="OccupancyGrid")
odom = Topic(name="odom", msg_type="Odometry")
plan = Topic(name="plan", msg_type="Path")
goal = Topic(name="goal", msg_type="PoseStamped")
battery = Topic(name="battery", msg_type="Float32")
question = Topic(name="question", msg_type="String")
answer = Topic(name="answer", msg_type="String")

RES, CELLS = 0.05, 400  # a 20 m x 20 m floor


def floor_plan() -> np.ndarray:
    cells = np.zeros((CELLS, CELLS), np.int8)
    cells[:4, :] = cells[-4:, :] = cells[:, :4] = cells[:, -4:] = 100
    cells[180:190, 40:250] = 100
    cells[250:400, 300:306] = 100
    cells[60:120, 280:340] = -1
    return cells


class Camera(BaseComponent):
    def custom_on_activate(self):
        h, w = 480, 640
        self._y, self._x = np.mgrid[0:h, 0:w]

    def _execution_step(self):
        t = time.time()
        frame = np.empty((480, 640, 3), np.uint8)
        frame[..., 0] = ((self._x + t * 120) % 256).astype(np.uint8)
        frame[..., 1] = ((self._y + t * 60) % 256).astype(np.uint8)
        frame[..., 2] = 128
        self.publish(camera, Image.from_numpy(frame, header=Header(stamp=Time.now(), frame_id="camera")))
        self.health_status.set_healthy()


class World(BaseComponent):
    """The floor plan (2 Hz), the robot driving a circle (odometry) and its battery."""

    def custom_on_activate(self):
        self._map = floor_plan().reshape(-1)
        self._t0 = time.time()
        self._n = 0

    def _execution_step(self):
        t = time.time() - self._t0
        x, y, yaw = 10 + 5 * math.cos(t / 8), 10 + 5 * math.sin(t / 8), t / 8 + math.pi / 2
        msg = Odometry(header=Header(stamp=Time.now(), frame_id="map"))
        msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
        msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        self.publish(odom, msg)
        self._n += 1
        if self._n % 10 == 1:
            info = MapMetaData(resolution=RES, width=CELLS, height=CELLS)
            self.publish(grid, OccupancyGrid(header=Header(stamp=Time.now(), frame_id="map"), info=info, data=self._map))
            self.publish(battery, Float32(data=100.0 - (t / 6) % 100))
        self.health_status.set_healthy()


class StraightPlanner(BaseComponent):
    """A stand-in planner: a straight line from the robot to each goal."""

    def _execution_step(self, msg=None, topic=None):
        robot = self.get_input(odom)
        if msg is not None and robot is not None:
            x0, y0 = robot.pose.pose.position.x, robot.pose.pose.position.y
            x1, y1 = msg.pose.position.x, msg.pose.position.y
            n = max(2, int(math.hypot(x1 - x0, y1 - y0) / 0.1))
            poses = [PoseStamped(pose=Pose()) for _ in range(n)]
            for i, p in enumerate(poses):
                p.pose.position.x, p.pose.position.y = x0 + (x1 - x0) * i / (n - 1), y0 + (y1 - y0) * i / (n - 1)
            self.publish(plan, Path(header=Header(stamp=Time.now(), frame_id="map"), poses=poses))
        self.health_status.set_healthy()


class Echo(BaseComponent):
    def _execution_step(self, msg=None, topic=None):
        if msg is not None:
            self.publish(answer, String(data=f"You said: {msg.data}"))
        self.health_status.set_healthy()


cam = Camera(component_name="camera", outputs=[camera], trigger=1 / 30)
world = World(component_name="world", outputs=[grid, odom, battery], trigger=0.05)
planner = StraightPlanner(component_name="planner", inputs=[odom], outputs=[plan], trigger=goal)
echo = Echo(component_name="chat", outputs=[answer], trigger=question)

launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[cam, world, planner, echo])
launcher.enable_ui(inputs=[question, goal], outputs=[camera, grid, odom, plan, answer, battery], port=options.port, host=options.host)
launcher.bringup()
