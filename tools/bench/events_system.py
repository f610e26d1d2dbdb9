"""The system ``emos bench events`` drives (run with ``emos run``; configured by environment).

EMOS_BENCH_MODE=events, EMOS_BENCH_EVENTS=N: ``listener`` is an ordinary subscriber of
/bench/trigger and reports each message's latency on /bench/topic_ns; N events are armed on the
trigger topic, one of which fires for every message and calls ``target.hit`` (another process),
whose first line reports the latency on /bench/event_ns. The others are evaluated and stay false.
EMOS_BENCH_FIRING=0: the N events are armed and evaluated on every message, none fires.

EMOS_BENCH_MODE=fallback: ``faulty`` reports COMPONENT_FAILURE when told to on /bench/fail; its
``on_component_fail`` fallback (a method of its own) reports the failure-to-action time on
/bench/fallback_ns and recovers. EMOS_BENCH_MODE=recover: the fallback is ``restart``.
"""
import os
import time

from emos import Action, BaseComponent, BaseComponentConfig, Event, Launcher, Topic
from emos.actions import restart
from emos.launcher import DEFAULT_MONITOR_DEFER_MS
from emos.msgs import Int64

MODE = os.environ.get("EMOS_BENCH_MODE", "events")
N_EVENTS = int(os.environ.get("EMOS_BENCH_EVENTS", "10"))
FIRING = os.environ.get("EMOS_BENCH_FIRING", "1") != "0"

trigger = Topic(name="/bench/trigger", msg_type="Int64")
topic_ns = Topic(name="/bench/topic_ns", msg_type="Int64")
event_ns = Topic(name="/bench/event_ns", msg_type="Int64")
fail_cmd = Topic(name="/bench/fail", msg_type="Int64")
fallback_ns = Topic(name="/bench/fallback_ns", msg_type="Int64")


class Listener(BaseComponent):
    def _execution_step(self, msg=None, topic=None):
        self.publish(topic_ns, Int64(data=time.monotonic_ns() - msg.data))
        self.health_status.set_healthy()


class Target(BaseComponent):
    def hit(self, sent_ns):
        self.publish(event_ns, Int64(data=time.monotonic_ns() - sent_ns))


class Faulty(BaseComponent):
    def _execution_step(self, msg=None, topic=None):
        self.failed_at = time.monotonic_ns()
        self.health_status.set_fail_component(component_names=["bench"])

    def recovered(self):
        self.publish(fallback_ns, Int64(data=time.monotonic_ns() - self.failed_at))
        self.health_status.set_healthy()
        return True


launcher = Launcher(multi_processing=True, max_restarts=100000, max_seconds=1.0,
                    monitor_nice=int(os.environ.get("EMOS_BENCH_MONITOR_NICE", "5")),
                    monitor_defer_ms=float(os.environ.get("EMOS_BENCH_MONITOR_DEFER_MS", DEFAULT_MONITOR_DEFER_MS)))
if MODE == "events":
    listener = Listener(component_name="listener", inputs=[trigger], outputs=[topic_ns], trigger=trigger)
    target = Target(component_name="target", outputs=[event_ns])
    events = {}
    if N_EVENTS:
        if FIRING:
            events[Event(trigger)] = Action(target.hit, args=(trigger.msg.data,))
        for k in range(N_EVENTS - 1 if FIRING else N_EVENTS):
            events[Event((trigger.msg.data < -k - 1) | (trigger.msg.data == -k))] = Action(target.hit, args=(trigger.msg.data,))
    launcher.add_pkg(components=[listener, target], events_actions=events or None)
else:
    faulty = Faulty(component_name="faulty", inputs=[fail_cmd], outputs=[fallback_ns], trigger=fail_cmd,
                    config=BaseComponentConfig(fallback_rate=1000.0))
    faulty.on_component_fail(action=Action(faulty.recovered) if MODE == "fallback" else restart(component=faulty))
    launcher.add_pkg(components=[faulty])
launcher.bringup()
