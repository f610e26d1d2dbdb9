"""Self-healing with fallbacks (seed recipe "fallback recipes"), both layers in one system.

    emos run recipes/events_and_resilience/fallback_recipes.py --duration 8

Intelligence layer: ``brain`` answers ``user_query`` through a primary model client; the primary
server is down, so inference fails (ALGORITHM_FAILURE). Its ``on_algorithm_fail`` and
``on_component_fail`` fallbacks call ``brain.change_model_client("local_backup_client")``, and the
next query is answered by the backup. Navigation layer: ``controller`` runs an algorithm that
fails to converge (ALGORITHM_FAILURE); its ladder restarts it once, then switches it to
PurePursuit. ``drive_manager`` loses its serial link once (SYSTEM_FAILURE) and is restarted.
``launcher.on_fail(action_name="restart")`` covers every other component.

Stand-ins (the real LLM, Controller and DriveManager live in other branches): ``Brain`` with two
model "clients" (``PrimaryClient`` raises ConnectionError like an unreachable server,
``LocalClient`` answers), ``Controller`` and ``DriveManager`` with the methods the seed recipe
calls. Everything the recipe wires (fallbacks, actions, launcher policy) is the real API.
"""
import os
import time

from attrs import define, field

from emos import Action, BaseComponent, BaseComponentConfig, Launcher, Topic
from emos.msgs import String

user_query = Topic(name="user_query", msg_type="String")
llm_response = Topic(name="llm_response", msg_type="String")


# --- stand-ins -------------------------------------------------------------------------------
class PrimaryClient:
    """A remote model whose server is down."""

    def inference(self, query: str) -> str:
        raise ConnectionError("primary model server unreachable")


class LocalClient:
    """A small local model (stand-in: answers in upper case)."""

    def inference(self, query: str) -> str:
        return f"[local backup] {query.upper()}"


class Brain(BaseComponent):
    """Stand-in for the LLM component: answers each query through its model client."""

    def __init__(self, model_client, **kwargs):
        super().__init__(**kwargs)
        self.model_client = model_client
        self.additional_model_clients = {}

    def _execution_step(self, msg=None, topic=None):
        try:
            answer = self.model_client.inference(msg.data)
        except ConnectionError as exc:
            self.get_logger().warning("[brain] inference failed: %s", exc)
            self.health_status.set_fail_algorithm(algorithm_names=[type(self.model_client).__name__])
            return
        self.publish(llm_response, String(data=answer))
        self.get_logger().info("[brain] answered: %s", answer)
        self.health_status.set_healthy()

    def change_model_client(self, client_name: str) -> bool:
        self.model_client = self.additional_model_clients[client_name]
        self.get_logger().info("[brain] switched to model client %r", client_name)
        self.health_status.set_healthy()
        return True


class User(BaseComponent):
    """Asks a question every second."""

    def _execution_step(self):
        self.publish(user_query, String(data=f"what do you see? ({time.strftime('%H:%M:%S')})"))
        self.health_status.set_healthy()


@define(kw_only=True)
class ControllerConfig(BaseComponentConfig):
    algorithm: str = field(default="DWA")


class Controller(BaseComponent):
    """Stand-in controller: DWA never converges here; PurePursuit does."""

    def _execution_step(self):
        if self.config.algorithm == "DWA":
            self.health_status.set_fail_algorithm(algorithm_names=["DWA"])
        else:
            self.health_status.set_healthy()

    def set_algorithm(self, algorithm: str) -> bool:
        self.config.algorithm = algorithm
        self.get_logger().info("[controller] algorithm switched to %s (pid %d)", algorithm, os.getpid())
        self.health_status.set_healthy()
        return True


class DriveManager(BaseComponent):
    """Stand-in driver: the serial link drops once, 1 s after the first start of the run."""

    def custom_on_activate(self):
        marker = self.node.ctx.run_dir / "drive_manager_link_dropped"  # once per run, not per restart
        self.link_drops = not marker.exists()
        marker.touch()
        self.started = time.monotonic()

    def _execution_step(self):
        if self.link_drops and time.monotonic() - self.started > 1.0:
            self.get_logger().warning("[drive_manager] serial link lost")
            self.health_status.set_fail_system(topic_names=["/dev/ttyUSB0"])
        else:
            self.health_status.set_healthy()


# --- the recipe (as in the seed) ---------------------------------------------------------------
llm_component = Brain(model_client=PrimaryClient(), inputs=[user_query], outputs=[llm_response], component_name="brain", trigger=user_query)
llm_component.additional_model_clients = {"local_backup_client": LocalClient()}
switch_to_backup = Action(method=llm_component.change_model_client, args=("local_backup_client",))
llm_component.on_component_fail(action=switch_to_backup, max_retries=3)
llm_component.on_algorithm_fail(action=switch_to_backup, max_retries=3)

controller = Controller(component_name="controller", config=ControllerConfig(loop_rate=10.0))
switch_algorithm_action = Action(method=controller.set_algorithm, args=("PurePursuit",))
controller.on_algorithm_fail(action=[Action(controller.restart), switch_algorithm_action], max_retries=1)

driver = DriveManager(component_name="drive_manager", config=BaseComponentConfig(loop_rate=10.0))
driver.on_system_fail(Action(driver.restart))

user = User(component_name="user", outputs=[user_query], config=BaseComponentConfig(loop_rate=1.0))

launcher = Launcher()
launcher.add_pkg(components=[llm_component, user], multiprocessing=True, package_name="automatika_embodied_agents")
launcher.add_pkg(components=[controller, driver], multiprocessing=True)
launcher.on_fail(action_name="restart")
launcher.fallback_rate = 1 / 10  # the global catch-all retries at most every 10 s
launcher.bringup()
