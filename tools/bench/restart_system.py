"""The system ``emos bench restart`` attacks: one component publishing its pid at 200 Hz."""
import os

from emos import BaseComponent, Launcher, Topic
from emos.msgs import Int64

KILLS = int(os.environ.get("EMOS_BENCH_KILLS", "200"))


class Victim(BaseComponent):
    def _execution_step(self):
        self.publish("victim/data", Int64(data=os.getpid()))
        self.health_status.set_healthy()


victim = Victim(component_name="victim", outputs=[Topic(name="victim/data", msg_type="Int64")])
victim.config.loop_rate = 200.0
launcher = Launcher(multi_processing=True, max_restarts=KILLS * 2 + 10, max_seconds=3600.0)
launcher.add_pkg(components=[victim], package_name="bench")
launcher.bringup()
