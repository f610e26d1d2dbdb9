"""Chaos workload: a fallback ladder under repeated algorithm failures, and an event Monitor.

``solver`` runs one of two algorithms (``primary``, ``backup``) at 20 Hz and reports
ALGORITHM_FAILURE while the one in use is broken. The chaos nemesis breaks the algorithm in use
from outside (``break_algorithm``, called through the control socket); the break is kept in the
run directory, so neither resetting nor restarting the process mends it, as with a real fault in
the algorithm's data or hardware. Its ladder, with two tries per step::

    solver.on_algorithm_fail(action=[reset_state, restart, switch_algorithm], max_retries=2)

so every break must run ``reset_state`` twice, ``restart`` twice, then ``switch_algorithm``
(which moves to the other algorithm; the broken one counts as repaired once it is out of use).
The supervisor's event log shows the ladder; the chaos checker verifies its order and retries.

An event (solver not healthy) makes the Monitor call ``alarm.raise_alarm``, which publishes on
``/alarms``: killing the Monitor must not disarm it.
"""
import json
import os

from emos import Action, BaseComponent, BaseComponentConfig, ComponentStatus, Event, Launcher, Topic
from emos.msgs import String

ALGORITHMS = ("primary", "backup")


class Solver(BaseComponent):
    def custom_on_activate(self):
        self.state_file = self.node.ctx.run_dir / "solver.json"
        state = self._load()
        self.algorithm = state["algorithm"]
        self.iterations = 0

    def _load(self) -> dict:
        try:
            return json.loads(self.state_file.read_text())
        except FileNotFoundError:
            return {"algorithm": ALGORITHMS[0], "broken": []}

    def _save(self, state: dict) -> None:
        tmp = self.state_file.with_suffix(".tmp")
        tmp.write_text(json.dumps(state))
        os.replace(tmp, self.state_file)

    def _execution_step(self):
        if self.algorithm in self._load()["broken"]:
            self.health_status.set_fail_algorithm(algorithm_names=[self.algorithm])
            return
        self.iterations += 1
        self.health_status.set_healthy()

    # -- the fault (called by the chaos nemesis) --------------------------------------------------
    def break_algorithm(self) -> str:
        state = self._load()
        state["broken"] = sorted(set(state["broken"]) | {self.algorithm})
        self._save(state)
        self.get_logger().warning("[solver] algorithm %s broken", self.algorithm)
        return self.algorithm

    # -- the ladder's steps ----------------------------------------------------------------------
    def reset_state(self) -> bool:
        self.iterations = 0
        self.get_logger().info("[solver] state reset (algorithm %s)", self.algorithm)
        return True

    def switch_algorithm(self) -> bool:
        state = self._load()
        old = self.algorithm
        self.algorithm = ALGORITHMS[(ALGORITHMS.index(old) + 1) % len(ALGORITHMS)]
        state["broken"] = [a for a in state["broken"] if a != old]  # out of use: repaired offline
        state["algorithm"] = self.algorithm
        self._save(state)
        self.get_logger().info("[solver] switched from %s to %s", old, self.algorithm)
        return True


class Alarm(BaseComponent):
    def raise_alarm(self) -> bool:
        self.publish(alarms, String(data="solver failing"))
        return True

    def _execution_step(self):
        self.health_status.set_healthy()


alarms = Topic(name="/alarms", msg_type="String")
solver = Solver(component_name="solver", config=BaseComponentConfig(loop_rate=20.0, fallback_rate=5.0))
solver.on_algorithm_fail(action=[Action(solver.reset_state), Action(solver.restart), Action(solver.switch_algorithm)], max_retries=2)
alarm = Alarm(component_name="alarm", outputs=[alarms], config=BaseComponentConfig(loop_rate=2.0))

solver_failing = Event(solver.status_topic.msg.status != ComponentStatus.STATUS_HEALTHY)

launcher = Launcher(multi_processing=True, heartbeat_timeout=2.0, fallback_reset_after=1.0)
launcher.add_pkg(components=[solver, alarm], package_name="workload", events_actions={solver_failing: Action(alarm.raise_alarm)})
launcher.bringup()
