"""A talker and a UI on the port given in EMOS_UI_TEST_PORT (which the test holds at first)."""
import os

from emos import BaseComponent, Launcher, Topic
from emos.msgs import String

words = Topic(name="words", msg_type="String")


class Talker(BaseComponent):
    def _execution_step(self):
        self.publish(words, String(data="still talking"))
        self.health_status.set_healthy()


launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[Talker(component_name="talker", outputs=[words], trigger=0.2)])
launcher.enable_ui(outputs=[words], port=int(os.environ["EMOS_UI_TEST_PORT"]))
launcher.bringup()
