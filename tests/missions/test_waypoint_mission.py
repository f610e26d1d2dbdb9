"""WaypointMission (actors/nav/missions): order, loops, resume and the unreachable-waypoint policy."""
import pytest

from emos.actors.nav.missions import WaitAtWaypoint, WaypointMission
from emos.actors.nav.missions.tasks import ActionAtWaypoint, TaskContext

pytestmark = pytest.mark.unit

WPS = [(1, 0), (2, 0), (3, 0), (4, 0)]


def _visit(m: WaypointMission) -> None:
    m.on_reached()
    m.on_task_done(True)


def test_unreachable_waypoint_is_skipped_and_reported_when_the_policy_goes_on():
    m = WaypointMission(WPS, stop_on_failure=False)
    _visit(m)
    m.on_failure("unreachable: the planner says no path to (2.00, 0.00)")
    assert m.state == "navigating" and m.index == 2  # went on to the next one
    _visit(m)
    _visit(m)
    assert m.state == "done" and not m.success
    assert m.missed == [(1, "unreachable: the planner says no path to (2.00, 0.00)")]
    assert m.reached == [0, 2, 3]


def test_unreachable_waypoint_stops_the_mission_when_the_policy_says_stop():
    m = WaypointMission(WPS, stop_on_failure=True)
    _visit(m)
    m.on_failure("not reached within 60 s")
    assert m.state == "failed" and m.finished
    assert "waypoint 1" in m.message and "not reached within 60 s" in m.message
    assert m.next_index == 1  # a resumed mission starts at the failed waypoint


def test_loops_and_distance_remaining():
    m = WaypointMission(WPS[:2], number_of_loops=2)
    for _ in range(5):
        _visit(m)
        assert not m.finished
    assert m.index == 1 and m.distance_remaining((1.0, 0.0)) == pytest.approx(1.0)
    _visit(m)
    assert m.state == "done" and m.loop == 3 and m.success
    assert m.distance_remaining((0.0, 0.0)) == 0.0


def test_forever_loops_until_cancelled_and_resume_index():
    m = WaypointMission(WPS, number_of_loops=-1, start_index=2)
    for _ in range(10):
        _visit(m)
    assert not m.finished and m.loop == 3 and m.index == 0


def test_task_failure_counts_as_the_waypoint_failing():
    m = WaypointMission(WPS, stop_on_failure=False)
    m.on_reached()
    m.on_task_done(False, "no image on /camera yet")
    assert m.missed == [(0, "task failed: no image on /camera yet")] and m.index == 1


def test_bad_waypoint_lists_are_refused_with_the_reason():
    with pytest.raises(ValueError, match="empty"):
        WaypointMission([])
    with pytest.raises(ValueError, match="waypoint 1 must be a finite"):
        WaypointMission([(0, 0), (float("nan"), 1)])
    with pytest.raises(ValueError, match="number_of_loops"):
        WaypointMission(WPS, number_of_loops=-2)
    with pytest.raises(ValueError, match="start_index 4"):
        WaypointMission(WPS, start_index=4)


def _ctx() -> TaskContext:
    return TaskContext(index=0, loop=0, waypoint=(0, 0, 0), latest=lambda name: None, cancelled=lambda: False)


def record(tag):
    record.calls.append(tag)
    return tag != "bad"


record.calls = []


def test_tasks_run_actions_and_wait():
    from emos import Action

    assert WaitAtWaypoint(0.0).run(_ctx()).ok
    assert ActionAtWaypoint(Action(method=record, args=("ok",))).run(_ctx()).ok
    out = ActionAtWaypoint(Action(method=record, args=("bad",))).run(_ctx())
    assert not out.ok and "returned False" in out.message
    assert record.calls == ["ok", "bad"]
    with pytest.raises(ValueError, match="waypoint_pause_duration"):
        WaitAtWaypoint(-1)


def test_photo_at_waypoint_saves_the_image_or_says_why_not(tmp_path):
    import numpy as np

    from emos.actors.nav.missions import PhotoAtWaypoint
    from emos.msgs import Image

    task = PhotoAtWaypoint(image_topic="/camera/image", save_dir=str(tmp_path))
    out = task.run(_ctx())
    assert not out.ok and out.message == "no image on /camera/image yet"
    img = Image(height=4, width=5, encoding="rgb8", data=np.full(60, 200, dtype=np.uint8))
    ctx = TaskContext(index=2, loop=1, waypoint=(0, 0, 0), latest=lambda name: img, cancelled=lambda: False)
    out = task.run(ctx)
    assert out.ok and (tmp_path / "waypoint_1_2.png").stat().st_size > 0
