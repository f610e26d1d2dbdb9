"""Multimodal planning: the spec's planning-models recipe ("go to the person"), ported.

    emos serve models --script recipes/models/responder.yaml &
    emos run recipes/planning_models.py --duration 60

An LLM (``sentence_parser``) pulls the object out of a go-to command; a planning VLM
(``go_to_x``, RoboBrain 2.0 with ``task="grounding"``) finds it in the RGBD camera's colour
image and publishes a ``Detections`` box with the depth image attached; the ``Planner`` takes
that box as its goal: box centre, median depth in the box, camera intrinsics, the camera's
place on the robot from the transform tree, the robot's pose -> a world goal; the Controller,
LocalMapper and DriveManager drive there.

What stands in for what, and why:
* the ``Simulator`` (pybullet, headless) is the robot and its RealSense: the demo house, the
  robot in its first room, and a person standing 2.8 m ahead (``PERSON_AT``). It publishes the
  RGBD stream on ``rgbd0``, the depth camera's intrinsics on the RealSense topic the Planner
  reads by default, the map, odometry, scan and ``/tf``;
* ``emos serve models`` is Ollama and RoboML: its scripted responder answers the sentence
  parser ("Go to the person." -> "person"), and for RoboML's grounding task it grounds the
  description with the server's own people detector (OpenCV HOG) in the image it was sent:
  a real answer about the picture, for the object classes that detector knows (people, faces);
* ``User`` (below) is the person giving the command: once the camera and the two model
  components are up it says ``COMMAND`` on ``goto_in`` (again after 20 s if nothing was
  grounded), and prints what each stage made of it: the parsed object, the grounded box, the
  Planner's goal next to the person's true position, and how far the robot still is.

The spec's code is unchanged but for the imports, ``rgbd0`` in the VLM's inputs (errata: the
step-by-step text says ``rgbd``), the VLM's name ``go_to_x`` (``go-to-x`` is no valid
component name, nor a valid ROS 2 node name), and the model clients' ports (``EMOS_MODELS_PORT``).
"""
import math
import os
import time

import numpy as np

from emos import BaseComponent, Launcher, Topic
from emos.actors.agents import LLM, VLM, OllamaClient, OllamaModel, RoboBrain2, RoboMLHTTPClient, VLMConfig
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.components import Controller, DriveManager, LocalMapper, Planner
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.person import Person
from emos.config.base import BaseComponentConfig
from emos.msgs import String

MODELS_PORT = int(os.environ.get("EMOS_MODELS_PORT", "8000"))
COMMAND = "Go to the person."
ROBOT_SPAWN = (1.0, 2.0, 0.0)  # x, y, yaw in the house's first room, facing +x
PERSON_AT = (3.8, 2.0)  # where the person stands (the end of their short walk into place)

# Start a Llama3.2 based llm component using ollama client
llama = OllamaModel(name="llama", checkpoint="llama3.2:3b")
llama_client = OllamaClient(llama, port=MODELS_PORT)

# Define LLM input and output topics including goal_point topic of type PoseStamped
goto_in = Topic(name="goto_in", msg_type="String")
llm_output = Topic(name="llm_output", msg_type="String")

# initialize the component
sentence_parser = LLM(
    inputs=[goto_in],
    outputs=[llm_output],
    model_client=llama_client,
    trigger=goto_in,
    component_name='sentence_parser'
)

sentence_parser.set_topic_prompt(goto_in, template="""You are a sentence parsing software.
Simply return the object description in the following command. {{ goto_in }}"""
)

# Start a RoboBrain2 based mllm component using RoboML client
robobrain = RoboBrain2(name="robobrain")
robobrain_client = RoboMLHTTPClient(robobrain, port=MODELS_PORT)

# Define VLM input/output topics
rgbd0 = Topic(name="rgbd0", msg_type="RGBD")
grounding_output = Topic(name="grounding_output", msg_type="Detections")

# Set the task in VLMConfig
config = VLMConfig(task="grounding")

# initialize the component
go_to_x = VLM(
    inputs=[llm_output, rgbd0],
    outputs=[grounding_output],
    model_client=robobrain_client,
    trigger=llm_output,
    config=config,
    component_name="go_to_x"  # errata: the spec's "go-to-x" is no valid component (or ROS 2 node) name
)

# Setup your robot configuration
my_robot = RobotConfig(
    model_type=RobotType.DIFFERENTIAL_DRIVE,
    geometry_type=RobotGeometry.Type.CYLINDER,
    geometry_params=np.array([0.1, 0.3]),
    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.2, max_acc=1.5, max_decel=2.5),
    ctrl_omega_limits=AngularCtrlLimits(
        max_vel=0.4, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3
    ),
)

# Setup components with default config, inputs and outputs
planner = Planner(component_name="planner")

# Set our grounding output as the goal_point in the planner component
planner.inputs(goal_point=grounding_output)

# Get a default Local Mapper component
mapper = LocalMapper(component_name="mapper")

# Get a default controller component
controller = Controller(component_name="controller")
# Configure Controller to use local map instead of direct sensor information
controller.direct_sensor = False

# Setup a default drive manager
driver = DriveManager(component_name="drive_manager")

# --- What runs here instead of the robot, its RealSense and a user (see the docstring) --------
# The person walks 0.2 m into place in the first seconds, then stands (the simulator's people
# are walkers; a walk of mode "once" ends standing).
person = Person(waypoints=np.array([(PERSON_AT[0], PERSON_AT[1] - 0.2), PERSON_AT]), speed=0.2, mode="once")
# A 400 x 300 camera with a 70 deg vertical field of view: the people detector needs a whole
# figure of >= 128 px, which the person is from up to ~2.9 m away.
sim = Simulator("sim", config=SimulatorConfig(world="house", spawn=ROBOT_SPAWN, camera_width=400, camera_height=300,
                                              camera_vfov_deg=70.0, moving_obstacles=[person]))
sim.outputs(rgbd=rgbd0, depth_camera_info=planner.get_in_topic("depth_camera_info"),
            map=Topic(name="/map", msg_type="OccupancyGrid"))


class User(BaseComponent):
    """Says COMMAND once the camera and the model components are up; reports each stage."""

    WATCHED = ("sentence_parser", "go_to_x", "planner")

    def __init__(self) -> None:
        self.camera_info = planner.get_in_topic("depth_camera_info")
        self.plan, self.odom = planner.get_out_topic("plan"), planner.get_in_topic("location")
        self.statuses = [Topic(name=f"{name}/status", msg_type="ComponentStatus") for name in self.WATCHED]
        super().__init__(component_name="user", inputs=[self.camera_info, llm_output, grounding_output, self.plan,
                                                        self.odom, *self.statuses],
                         outputs=[goto_in], config=BaseComponentConfig(loop_rate=2.0))

    def custom_on_activate(self) -> None:
        self.said_at: float | None = None
        self.seen: dict = {}
        self.last_print = 0.0

    def _fresh(self, topic: Topic):
        """The topic's latest message if it is one this step has not reported yet."""
        msg = self.get_input(topic)
        if msg is None or self.seen.get(topic.name) is msg:
            return None
        self.seen[topic.name] = msg
        return msg

    def _execution_step(self) -> None:
        self.health_status.set_healthy()
        now = time.monotonic()
        ready = self.get_input(self.camera_info) is not None and all(
            self.get_input(t) is not None for t in self.statuses)
        grounded = self.seen.get(grounding_output.name) is not None
        if ready and (self.said_at is None or (not grounded and now - self.said_at > 20.0)):
            self.said_at = now
            self.publish(goto_in, String(data=COMMAND))
            print(f"[user] said on {goto_in.name}: {COMMAND!r}", flush=True)
        parsed = self._fresh(llm_output)
        if parsed is not None:
            print(f"[user] sentence_parser: the object is {parsed.data!r}", flush=True)
        found = self._fresh(grounding_output)
        if found is not None:
            boxes = ", ".join("[" + ", ".join(f"{v:.0f}" for v in b) + "]" for b in found.boxes)
            depth = "with" if found.image is not None else "WITHOUT"
            print(f"[user] go_to_x grounded it: {len(found.labels)} box(es) {boxes} {depth} the depth image", flush=True)
        plan = self._fresh(self.plan)
        if plan is not None and len(plan.poses):
            end = plan.poses[-1].pose.position
            goal = self.seen.get("goal")
            if goal is None or math.dist(goal, (end.x, end.y)) > 0.05:  # a new goal, not a re-plan
                self.seen["goal"] = (end.x, end.y)
                print(f"[user] planner goal ({end.x:.2f}, {end.y:.2f}); the person stands at {PERSON_AT}: "
                      f"{math.dist((end.x, end.y), PERSON_AT):.2f} m apart", flush=True)
        odom = self.get_input(self.odom)
        if odom is not None and self.seen.get("goal") and now - self.last_print >= 2.0:
            self.last_print = now
            p = odom.pose.pose.position
            print(f"[user] robot at ({p.x:.2f}, {p.y:.2f}), {math.dist((p.x, p.y), PERSON_AT):.2f} m from the person",
                  flush=True)


user = User()

launcher = Launcher()

# Add the intelligence components
launcher.add_pkg(components=[sentence_parser, go_to_x], ros_log_level="warn",
                 package_name="automatika_embodied_agents",
                 executable_entry_point="executable",
                 multiprocessing=True)

# Add the navigation components
launcher.kompass(components=[planner, controller, mapper, driver])

# The simulated robot and the user
launcher.add_pkg(components=[sim, user], multiprocessing=True)

# Set the robot config for all components as defined above and bring up
launcher.robot = my_robot
launcher.bringup()
