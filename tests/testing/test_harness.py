"""emos.testing.ComponentHarness: a component's real node, driven by hand on a manual clock."""
from __future__ import annotations

import math

import pytest

from emos import BaseComponent, Topic
from emos import msgs as M
from emos.core import clock
from emos.core.lifecycle import Transition
from emos.testing import ComponentHarness
from emos.transport.context import SHM_DIR

pytestmark = pytest.mark.unit


class Counter(BaseComponent):
    """Timed: counts its steps and publishes the count; remembers the clock at each step."""

    def custom_on_activate(self) -> None:
        self.n, self.times = 0, []

    def _execution_step(self) -> None:
        self.n += 1
        self.times.append(clock.now())
        self.publish("/count", M.Int32(data=self.n))
        self.health_status.set_healthy()


class Echo(BaseComponent):
    """Event: one step per message on /in; reports the age of /other at each step."""

    def custom_on_activate(self) -> None:
        self.ages = []

    def _execution_step(self, msg=None, topic=None) -> None:
        if msg.data < 0:
            raise ValueError("negative input")
        self.ages.append(self.input_age("/other"))
        self.publish("/out", M.Int32(data=msg.data * 2))
        self.health_status.set_healthy()


def _segments(ctx_prefix: str) -> list[str]:
    return [p.name for p in SHM_DIR.iterdir() if p.name.startswith(ctx_prefix)]


def test_a_timed_component_steps_once_per_tick_on_the_manual_clock():
    c = Counter(component_name="counter", outputs=[Topic(name="count", msg_type="Int32")])
    c.config.loop_rate = 10.0
    with ComponentHarness(c, start_time=100.0) as h:
        prefix = h._ctx.shm_prefix
        assert _segments(prefix), "the harness runs on real rings"
        h.advance(1.0)
        assert c.n == 10 and [m.data for m in h.outputs("count")] == list(range(1, 11))
        assert c.times == pytest.approx([100.1 + 0.1 * i for i in range(10)])
        assert clock.now() == pytest.approx(101.0) and h.time == pytest.approx(101.0)
        h.advance(0.05)  # half a period: no step is due
        assert c.n == 10 and h.outputs("count") == []
        h.advance(0.05)
        assert c.n == 11 and h.latest("count").data == 11
        assert h.health.is_healthy
    assert not _segments(prefix)  # every ring of the harness's run is gone
    assert abs(clock.now() - __import__("time").time()) < 60  # the process is back on the wall clock


def test_an_event_component_steps_on_what_is_fed_and_ages_follow_the_manual_clock():
    c = Echo(component_name="echo", inputs=[Topic(name="in", msg_type="Int32"), Topic(name="other", msg_type="Int32")],
             outputs=[Topic(name="out", msg_type="Int32")])
    c.trigger = c.in_topics[0]
    with ComponentHarness(c) as h:
        h.feed("/other", M.Int32(data=0))
        h.advance(2.5)  # nothing on the trigger: no step
        assert h.outputs("/out") == [] and c.ages == []
        h.feed("in", M.Int32(data=4))
        h.feed("in", M.Int32(data=5))
        h.step()
        assert [m.data for m in h.outputs("/out")] == [8, 10]
        assert c.ages == [pytest.approx(2.5), pytest.approx(2.5)]  # simulated seconds, whatever the wall clock did
        h.feed("in", M.Int32(data=-1))
        h.step()
        assert h.health.is_component_fail and "negative input" in h.health.to_msg().message


def test_bad_use_is_refused_naming_the_thing():
    c = Counter(component_name="counter", outputs=[Topic(name="count", msg_type="Int32")])
    with pytest.raises(ValueError, match="start_time must be a finite time >= 0 s, got nan"):
        ComponentHarness(c, start_time=math.nan)
    with pytest.raises(ValueError, match="tick must be a finite period > 0 s, got 0"):
        ComponentHarness(c, tick=0)
    with ComponentHarness(c) as h:
        with pytest.raises(KeyError, match="component 'counter' has no input '/nope'; inputs: "):
            h.feed("nope", M.Int32(data=1))
        with pytest.raises(KeyError, match="has no output '/nope'; outputs: \\['/count'\\]"):
            h.outputs("/nope")
        with pytest.raises(ValueError, match="advance takes a finite number of seconds >= 0, got -1"):
            h.advance(-1)
        with pytest.raises(RuntimeError, match="already running"):
            ComponentHarness(c)
    with pytest.raises(TypeError, match="drives a BaseComponent, got str"):
        ComponentHarness("counter")


# ------------------------------------------------------------------ closed loops, records, services

class Follower(BaseComponent):
    """Timed: publishes the last /target it got, plus one; serves /follower/reset (a Trigger)."""

    def custom_on_configure(self) -> None:
        self.create_service("follower/reset", M.TriggerRequest, M.TriggerResponse, self._reset)

    def custom_on_activate(self) -> None:
        self.offset = 1

    def _reset(self, request):
        self.offset = 100
        self.publish("/cmd", M.Int32(data=-1))  # a service may publish, outside any step
        return M.TriggerResponse(success=True, message=f"reset at {clock.now():.2f}")

    def _execution_step(self) -> None:
        target = self.get_input("/target")
        if target is not None:
            self.publish("/cmd", M.Int32(data=target.data + self.offset))
        self.health_status.set_healthy()


def _follower():
    c = Follower(component_name="follower", inputs=[Topic(name="target", msg_type="Int32")], outputs=[Topic(name="cmd", msg_type="Int32")])
    c.config.loop_rate = 10.0
    return c


def test_each_tick_closes_the_loop_and_the_record_keeps_more_than_a_ring_holds():
    """A world that answers each command before the next tick: ``each_tick`` runs with the clock
    at the previous tick, and sees what the component published at it."""
    seen = []

    def world(h: ComponentHarness) -> None:
        last = h.latest("/cmd")
        seen.append((round(h.time, 3), None if last is None else last.data))
        h.feed("/target", M.Int32(data=0 if last is None else last.data))

    with ComponentHarness(_follower()) as h:
        start = h.mark()
        h.advance(30.0, each_tick=world)  # 300 ticks: far more than the 64 a ring of /cmd keeps
        assert seen[:3] == [(0.0, None), (0.1, 1), (0.2, 2)]
        assert [m.data for m in h.outputs("/cmd")] == list(range(1, 301))
        assert h.outputs("/cmd") == []  # read on from where it last read
        middle = h.mark()
        h.advance(0.2, each_tick=world)
        assert [m.data for m in h.since("/cmd", middle)] == [301, 302]
        assert len(h.since("/cmd", start)) == 302  # since() does not move outputs()
        assert [(t, m.data) for t, m in h.since("/cmd", middle, times=True)] == [(pytest.approx(30.1), 301), (pytest.approx(30.2), 302)]
        assert [m.data for m in h.outputs("/cmd")] == [301, 302]


def test_play_feeds_a_stream_one_message_per_period_on_the_clock():
    with ComponentHarness(_follower(), start_time=5.0) as h:
        h.play("/target", [M.Int32(data=d) for d in (10, 20, 30)])
        assert h.time == pytest.approx(5.3)
        assert [m.data for m in h.outputs("/cmd")] == [11, 21, 31]
        h.play("target", [M.Int32(data=40), M.Int32(data=50)], period=0.5)  # 5 steps per message
        assert [m.data for m in h.outputs("/cmd")] == [41] * 5 + [51] * 5 and h.time == pytest.approx(6.3)
        with pytest.raises(ValueError, match="play takes a finite period > 0 s, got 0"):
            h.play("/target", [M.Int32(data=1)], period=0)


def test_call_serves_a_service_through_its_socket_without_moving_the_clock():
    with ComponentHarness(_follower(), start_time=2.0) as h:
        h.feed("/target", M.Int32(data=1))
        h.advance(0.1)
        assert h.outputs("/cmd")[-1].data == 2
        res = h.call("/follower/reset", M.TriggerRequest())
        assert res.success and res.message == "reset at 2.10" and h.time == pytest.approx(2.1)
        assert [m.data for m in h.outputs("/cmd")] == [-1]  # what the service published is recorded
        h.advance(0.1)
        assert h.latest("/cmd").data == 101
        with pytest.raises(KeyError, match="serves no service 'follower/nope' while active; services: \\['follower/reset'\\]"):
            h.call("follower/nope", M.TriggerRequest())


class Worker(BaseComponent):
    """Timed: its first step starts a thread that publishes once it is released."""

    def custom_on_activate(self) -> None:
        import threading

        self.release, self.thread = threading.Event(), None

    def _execution_step(self) -> None:
        import threading

        if self.thread is None:
            self.thread = threading.Thread(target=lambda: self.release.wait(30) and self.publish("/count", M.Int32(data=7)), daemon=True)
            self.thread.start()
        self.health_status.set_healthy()


def test_wait_for_runs_the_loop_until_a_components_own_thread_has_published():
    c = Worker(component_name="worker", outputs=[Topic(name="count", msg_type="Int32")])
    c.config.loop_rate = 1.0
    with ComponentHarness(c) as h:
        h.advance(h.tick)
        with pytest.raises(TimeoutError, match="component 'worker': no count of 7 within 0.2 s of wall time \\(clock at 1.000 s\\)"):
            h.wait_for(lambda: h.latest("/count"), timeout=0.2, what="count of 7")
        c.release.set()
        assert h.wait_for(lambda: h.latest("/count")).data == 7 and h.time == pytest.approx(1.0)  # the clock stood still
        c.thread.join(5)


def test_triggering_messages_that_arrive_before_activation_are_stepped_once_active(caplog):
    """A query published while its component is still configuring or activating (a model that
    loads at activation) is answered once the component is active, not taken and dropped."""
    c = Echo(component_name="echo", inputs=[Topic(name="in", msg_type="Int32"), Topic(name="other", msg_type="Int32")],
             outputs=[Topic(name="out", msg_type="Int32")])
    c.trigger = c.in_topics[0]
    c.in_topics[0].qos_profile.queue_size = 3
    with ComponentHarness(c, activate=False) as h:
        for batch in ((0, 1, 2), (3, 4)):
            for i in batch:
                h.feed("in", M.Int32(data=i))
            h.step()  # the node takes them while configured, not active: no step yet
        assert h.outputs("/out") == []
        with caplog.at_level("WARNING"):
            h.activate()
        assert [m.data for m in h.outputs("/out")] == [4, 6, 8]  # the newest queue_size, in order
        assert "2 message(s) on /in arrived while the component was not active" in caplog.text
        h.feed("in", M.Int32(data=7))
        h.step()
        assert [m.data for m in h.outputs("/out")] == [14]


class Served(BaseComponent):
    """Declares a service at configure, as the Planner and the MapServer do."""

    def custom_on_configure(self) -> None:
        self.create_service(f"{self.component_name}/ping", M.TriggerRequest, M.TriggerResponse, lambda req: M.TriggerResponse(success=True))

    def _execution_step(self) -> None:
        self.health_status.set_healthy()


def test_a_component_configured_again_after_cleanup_serves_each_service_once():
    c = Served(component_name="served")
    with ComponentHarness(c) as h:
        assert [name for _, name, _ in h.node.interfaces()] == ["served/ping"]
        h.deactivate()
        h._transition(Transition.CLEANUP)
        h._transition(Transition.CONFIGURE)
        h.activate()
        assert len(h.node._extra_servers) == 1
        assert h.call("served/ping", M.TriggerRequest()).success
