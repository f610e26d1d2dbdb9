"""StartVisionTracking sends its goal once the controller serves ``track_vision_target`` (the
controller may come up after it) and never after it was deactivated. A real ActionServer on real
Unix sockets stands in for the Controller's."""
import threading
import time

import pytest

from emos.actors.nav.components.interfaces import TrackVisionTargetFeedback, TrackVisionTargetGoal, TrackVisionTargetResult
from emos.actors.nav.components.track_target import StartVisionTracking
from emos.core.services import ActionServer
from emos.transport.context import RunContext, set_current
from tests.core.test_wait_for_server import _ServerLoop

pytestmark = pytest.mark.process


@pytest.fixture
def run():
    ctx = RunContext.create()
    set_current(ctx)
    servers = _ServerLoop()
    yield ctx, servers
    servers.close()
    set_current(None)
    ctx.remove_everything()


def _controller(goals: list):
    def execute(handle):
        goals.append((handle.goal_id, handle.goal.label))
        return TrackVisionTargetResult(success=True, message="target followed")
    return execute


def _start(component: StartVisionTracking) -> threading.Thread:
    component._stop = threading.Event()
    thread = threading.Thread(target=component._run, daemon=True)
    thread.start()
    return thread


def test_the_goal_waits_for_a_controller_that_starts_later_and_is_sent_once(run):
    ctx, servers = run
    goals: list = []
    start = StartVisionTracking(component_name="start", controller_name="controller", label="person")
    thread = _start(start)
    time.sleep(0.8)  # at least one attempt has found nothing serving
    assert goals == [] and start.result is None
    servers.start(ActionServer(ctx, "controller/track_vision_target", TrackVisionTargetGoal, TrackVisionTargetFeedback,
                               TrackVisionTargetResult, _controller(goals)))
    thread.join(60)
    assert not thread.is_alive()
    assert [label for _, label in goals] == ["person"], "one goal"
    assert start.result is not None and start.result.success


def test_no_goal_after_deactivation(run):
    ctx, servers = run
    goals: list = []
    start = StartVisionTracking(component_name="start", controller_name="controller", label="person")
    thread = _start(start)
    time.sleep(0.8)
    assert start._stop is not None
    start._stop.set()  # what custom_on_deactivate does first
    thread.join(60)
    assert not thread.is_alive(), "the wait ends with the deactivation"
    servers.start(ActionServer(ctx, "controller/track_vision_target", TrackVisionTargetGoal, TrackVisionTargetFeedback,
                               TrackVisionTargetResult, _controller(goals)))
    time.sleep(0.5)
    assert goals == [] and start.result is None
