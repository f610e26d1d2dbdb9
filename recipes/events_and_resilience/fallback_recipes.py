"""Self-healing with fallbacks (seed recipe "fallback recipes"): both layers in one system.

    emos serve models --script recipes/models/responder.yaml &                # the local backup (Ollama)
    emos serve models --script recipes/models/responder.yaml --port 8001 &    # the "remote" primary (RoboML)
    emos run recipes/events_and_resilience/fallback_recipes.py --duration 40
    # ... and shut the primary down while it runs (the spec's own test): kill %2

Intelligence layer (the spec's code): the ``LLM`` ``brain`` answers ``user_query`` through its
primary client (RoboML HTTP, ``EMOS_PRIMARY_PORT``, default 8001). When that server is down at
start-up (COMPONENT_FAILURE) or goes down while the robot runs, ``on_component_fail`` /
``on_algorithm_fail`` call ``brain.change_model_client("local_backup_client")`` and the
questions are answered by the backup (Ollama API, ``EMOS_MODELS_PORT``, default 8000). The LLM's
own request-level failover (docs/agents.md) may swap on the request that met the dead server
before the ladder acts; the ladder's action then finds the backup in place.

Navigation layer (the spec's code): the ``Controller`` runs DWA; its ``on_algorithm_fail`` ladder
restarts it once, then switches it to PurePursuit. The ``DriveManager`` restarts on a SYSTEM
failure. ``launcher.on_fail(action_name="restart")`` (at most every 10 s) covers every component
without a ladder of its own.

What is real and what stands in:
* real: the ``LLM`` with both model clients against ``emos serve models`` (the scripted responder
  stands in for Qwen and Llama; recipes/models/responder.yaml), the ``Controller``,
  ``DriveManager`` and the ``Simulator`` (pybullet, headless: the demo house), the supervisor's
  fallback driver that runs the ladders;
* the fault on the navigation side is a closed door: a box (not in any map) fills the doorway the
  robot's route goes through, so DWA makes no progress. ``progress_timeout=3.0`` in the
  Controller's config makes that stall an ALGORITHM failure (the spec's "solver fails to
  converge"), so the ladder runs: restart, then PurePursuit, which cannot pass a closed door
  either; the ladder is then spent and the Controller shows GAVE_UP in ``emos status``. The
  Controller's restart also takes its commands away from the DriveManager for a moment, which
  stops the robot and reports a SYSTEM failure naming ``/control``: the DriveManager's
  ``on_system_fail`` restart (the spec's "loose cable" case) acts on that;
* stand-ins: ``Route`` publishes the global plan through the doorway (a Planner is not the point
  here), and ``User`` asks the brain a question every 3 s and prints the answers.
"""
import os

import numpy as np

from emos import Action, BaseComponent, BaseComponentConfig, Launcher, Topic
from emos.actors.agents import LLM, LLMConfig, OllamaClient, OllamaModel, RoboMLHTTPClient, TransformersLLM
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.components import Controller, ControllerConfig, DriveManager
from emos.actors.nav.components.convert import path_msg
from emos.actors.nav.controllers import ControllersID
from emos.actors.sim import Box, Simulator, SimulatorConfig
from emos.msgs import String

MODELS_PORT = int(os.environ.get("EMOS_MODELS_PORT", "8000"))  # the local backup (Ollama API)
PRIMARY_PORT = int(os.environ.get("EMOS_PRIMARY_PORT", "8001"))  # the "remote" primary (RoboML HTTP)

# ============================ Intelligence layer: model fallback ============================
# 1. Define the Models and Clients
# Primary: A powerful model hosted remotely
primary_model = TransformersLLM(name="qwen_heavy", checkpoint="Qwen/Qwen2.5-1.5B-Instruct")
primary_client = RoboMLHTTPClient(model=primary_model, port=PRIMARY_PORT)
# Backup: A smaller model running locally
backup_model = OllamaModel(name="llama_local", checkpoint="llama3.2:3b")
backup_client = OllamaClient(model=backup_model, port=MODELS_PORT)

# 2. Define Topics
user_query = Topic(name="user_query", msg_type="String")
llm_response = Topic(name="llm_response", msg_type="String")

# 3. Configure the LLM Component
llm_component = LLM(
    inputs=[user_query],
    outputs=[llm_response],
    model_client=primary_client,
    trigger=user_query,  # errata: the spec leaves the trigger out
    component_name="brain",
    config=LLMConfig(stream=True),
)

# 4. Register the Backup Client
llm_component.additional_model_clients = {"local_backup_client": backup_client}

# 5. Define the Fallback Action
switch_to_backup = Action(method=llm_component.change_model_client, args=("local_backup_client",))

# 6. Bind Failures to the Action
llm_component.on_component_fail(action=switch_to_backup, max_retries=3)
llm_component.on_algorithm_fail(action=switch_to_backup, max_retries=3)

# ======================= Navigation layer: algorithm and system fallback =======================
my_robot = RobotConfig(
    model_type=RobotType.DIFFERENTIAL_DRIVE,
    geometry_type=RobotGeometry.Type.CYLINDER,
    geometry_params=np.array([0.1, 0.3]),
    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.4, max_acc=1.5, max_decel=2.5),
    ctrl_omega_limits=AngularCtrlLimits(max_vel=0.4, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
)

# Select the primary control algorithm (a stall of 3 s is an ALGORITHM failure: see the module doc)
controller = Controller(component_name="controller", config=ControllerConfig(progress_timeout=3.0))
controller.algorithm = ControllersID.DWA

# Define the fallback: switch to PurePursuit
switch_algorithm_action = Action(method=controller.set_algorithm, args=(ControllersID.PURE_PURSUIT,))

# Fallback sequence: restart first, then switch algorithm if it fails again
controller.on_algorithm_fail(action=[Action(controller.restart), switch_algorithm_action], max_retries=1)

driver = DriveManager(component_name="drive_manager")

# Restart on system failure (unlimited retries for transient hardware glitches)
driver.on_system_fail(Action(driver.restart))

# --- The simulated robot, its closed door, its route and its user (see the module doc) -----------
DOORWAY_Y = 3.19  # the middle wall (x = 5) of the demo house has its doorway at y in [2.7, 3.68]
SPAWN = (3.8, DOORWAY_Y, 0.0)
ROUTE = np.array([(SPAWN[0] + d, DOORWAY_Y) for d in np.arange(0.0, 3.2, 0.1)])  # through the doorway
closed_door = Box(center=(5.0, DOORWAY_Y), size=(0.12, 1.1), height=1.2, color=(0.45, 0.3, 0.2, 1.0))
sim = Simulator("sim", config=SimulatorConfig(world="house", spawn=SPAWN, obstacles=[closed_door]))
plan = controller.get_in_topic("plan")


class Route(BaseComponent):
    """The global plan through the doorway, sent every second (the same plan: a restarted
    Controller finds it, a running one does not start over)."""

    def custom_on_activate(self):
        self.plan = path_msg(ROUTE, "map")

    def _execution_step(self):
        self.publish(plan, self.plan)
        self.health_status.set_healthy()


class User(BaseComponent):
    """Asks the brain a question every 3 s; prints each answer (each piece of a streamed one)."""

    def custom_on_activate(self):
        self.asked = 0
        self.create_timer(3.0, self.ask)

    def ask(self):
        self.asked += 1
        self.publish(user_query, String(data=f"Hello robot, question {self.asked}: what do you see?"))

    def _execution_step(self, msg=None, topic=None):
        print(f"[user] the brain answered: {msg.data!r}", flush=True)
        self.health_status.set_healthy()


route = Route(component_name="route", outputs=[plan], config=BaseComponentConfig(loop_rate=1.0))
user = User(component_name="user", inputs=[llm_response], outputs=[user_query], trigger=llm_response)

# 7. Launch
launcher = Launcher()
launcher.add_pkg(components=[sim, route, user], multiprocessing=True, package_name="simulation")  # the robot first
launcher.add_pkg(components=[llm_component], multiprocessing=True, package_name="automatika_embodied_agents")
launcher.add_pkg(components=[controller, driver], multiprocessing=True, package_name="kompass")
launcher.robot = my_robot
# Global catch-all
launcher.on_fail(action_name="restart")
launcher.fallback_rate = 1 / 10  # 0.1 Hz (one retry every 10 seconds)
launcher.bringup()
