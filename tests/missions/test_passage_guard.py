"""The passage guard (actors/nav/missions/passages.py): the band of where movers walked, the
prediction from earlier walks, and when the robot is held before the band stretch of its path.

The scene is the demo house's person (``HOUSE_PERSON_PATH``, 0.6 m/s back and forth: up x = 4.2,
then along y = 3.25 through the middle doorway to x = 7.0) seen for a minute, and the robot's
two ways through that doorway on the patrol."""
import math

import numpy as np
import pytest

from emos.actors.nav.missions.passages import MoverMemory, PassageGuardConfig, check_passage, path_ahead

pytestmark = pytest.mark.unit

PATH = np.array([(4.2, 0.6), (4.2, 3.25), (7.0, 3.25)])
SEG = np.hypot(*np.diff(PATH, axis=0).T)
CUM = np.r_[0.0, np.cumsum(SEG)]
LENGTH = float(CUM[-1])
SPEED = 0.6
PERIOD = 2 * LENGTH / SPEED
ROBOT_RADIUS, PERSON = 0.2, 0.22
# The robot's ways through the middle doorway (x = 5, y 2.76 to 3.74) on the patrol.
LEFT_TO_RIGHT = np.array([(3.0, 2.5), (3.55, 2.85), (4.5, 3.2), (5.0, 3.25), (5.5, 3.1), (6.2, 2.8), (7.0, 2.5)])
RIGHT_TO_LEFT = np.array([(8.0, 4.6), (8.0, 4.0), (7.5, 3.7), (6.0, 3.3), (5.0, 3.25), (4.0, 3.4), (3.0, 3.8), (2.5, 4.2)])


def person(t: float) -> tuple[np.ndarray, np.ndarray]:
    """The blind person's centre and velocity at ``t`` s (pingpong along PATH)."""
    s, sign = (t * SPEED) % (2 * LENGTH), 1.0
    if s > LENGTH:
        s, sign = 2 * LENGTH - s, -1.0
    k = min(int(np.searchsorted(CUM, s, side="right")) - 1, len(SEG) - 1)
    u = (PATH[k + 1] - PATH[k]) / SEG[k]
    return PATH[k] + u * (s - CUM[k]), u * SPEED * sign


def watched(seconds: float = 60.0) -> MoverMemory:
    memory = MoverMemory()
    for t in np.arange(0.0, seconds, 0.1):
        c, v = person(float(t))
        memory.observe(float(t), c[None], v[None])
    return memory


def hold_point(memory: MoverMemory, path: np.ndarray, config: PassageGuardConfig) -> np.ndarray:
    """Where a robot driving ``path`` is first held: just before the band."""
    pts = path_ahead(path, path[0], 50.0)
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(pts, axis=0).T))]
    fine = np.arange(0.0, s[-1], 0.05)
    xy = np.c_[np.interp(fine, s, pts[:, 0]), np.interp(fine, s, pts[:, 1])]
    first = int(np.argmax(memory.band_gap(xy) < config.band_clearance))
    return xy[max(first - 4, 0)]


def verdicts(memory: MoverMemory, path: np.ndarray, config: PassageGuardConfig, t0: float = 60.0) -> list[tuple[float, bool]]:
    robot = hold_point(memory, path, config)
    out = []
    for t in np.arange(t0, t0 + PERIOD, 0.25):
        c, v = person(float(t))
        out.append((float(t), check_passage(path, robot, memory, float(t), c[None], v[None], np.array([PERSON]),
                                            ROBOT_RADIUS, config).hold))
    return out


def drive_through(path: np.ndarray, start_xy: np.ndarray, t_start: float, config: PassageGuardConfig) -> float:
    """Least gap (m) between the robot driving ``path`` from ``start_xy`` (after start_delay s, at
    config.speed) and the walking person."""
    pts = path_ahead(path, start_xy, 50.0)
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(pts, axis=0).T))]
    least = math.inf
    for tau in np.arange(0.0, config.start_delay + s[-1] / config.speed, 0.1):
        along = min(max(tau - config.start_delay, 0.0) * config.speed, s[-1])
        r = np.array([np.interp(along, s, pts[:, 0]), np.interp(along, s, pts[:, 1])])
        least = min(least, float(np.hypot(*(r - person(t_start + tau)[0]))) - ROBOT_RADIUS - PERSON)
    return least


def test_band_is_where_the_person_walked():
    memory = watched()
    gaps = memory.band_gap(np.array([(4.2, 2.0), (6.0, 3.25), (2.5, 2.0), (7.0, 2.5), (8.0, 5.5)]))
    assert gaps[0] < 0.05 and gaps[1] < 0.05
    assert gaps[2] > 1.5 and gaps[3] > 0.7 and gaps[4] > 2.0  # the patrol's rooms are off the band
    assert np.isinf(MoverMemory().band_gap(np.zeros((1, 2))))[0]


def test_prediction_from_an_earlier_walk_turns_where_the_person_turned():
    """Walking +x towards the end of its way at x = 7.0: at constant velocity it walks on into
    the room; as it walked before, it turns and comes back through the doorway."""
    memory = watched()
    t = 60.0 + (8.0 - (60.0 % PERIOD)) % PERIOD  # 8 s into a lap: on y = 3.25, walking +x
    c, v = person(t)
    assert v[0] > 0.5
    times = np.array([0.0, 3.0, 5.0])
    preds = memory.predict(t, c, v, times)
    assert len(preds) >= 2
    constant, learned = preds[:2]  # then the same walk a little earlier and later
    assert constant[-1, 0] > 9.0
    truth = np.array([person(t + dt)[0] for dt in times])
    assert np.allclose(learned, truth, atol=0.15)
    assert memory.predict(t, c, np.zeros(2), times)[0].shape == (3, 2)  # a standing track: constant only


def test_memory_forgets_after_its_time():
    memory = MoverMemory(memory=10.0)
    for t in np.arange(0.0, 30.0, 0.1):
        c, v = person(float(t))
        memory.observe(float(t), c[None], v[None])
    assert memory.samples()[:, 0].min() >= 30.0 - 10.0 - 0.2
    memory.observe(31.0, np.zeros((1, 2)), np.zeros((1, 2)))  # a standing track is not a walk
    assert memory.samples()[-1, 0] < 31.0



def test_the_band_outlasts_the_walks_for_band_memory():
    """The walks are forgotten after ``memory`` s, the band they walked after ``band_memory``
    s (the give-way's yield moves keep out of it), also across a clock that went back."""
    memory = MoverMemory(memory=10.0, band_memory=60.0)
    for t in np.arange(0.0, 5.0, 0.1):  # a walk along y = 1
        memory.observe(float(t), np.array([[float(t), 1.0]]), np.array([[1.0, 0.0]]))
    memory.observe(30.0, np.array([[0.0, 3.0]]), np.array([[1.0, 0.0]]))  # one sample elsewhere, 25 s later
    assert np.allclose(memory.band_cells(), [[0.0, 3.0]])
    lasting = memory.lasting_band_cells(30.0)
    assert len(lasting) >= 40 and np.allclose(np.sort(np.unique(lasting[:, 1])), [1.0, 3.0])
    memory.observe(2.0, np.array([[0.0, 3.5]]), np.array([[1.0, 0.0]]))  # the clock went back 28 s
    assert len(memory.lasting_band_cells(2.0)) == len(lasting) + 1
    assert np.allclose(memory.lasting_band_cells(62.0)[:, 1], [3.5])  # the walk and the sample went by
    assert len(memory.lasting_band_cells(200.0)) == 0
    assert MoverMemory(memory=10.0, band_memory=5.0).band_memory == 10.0  # never shorter than the walks'


@pytest.mark.parametrize("path", [LEFT_TO_RIGHT, RIGHT_TO_LEFT], ids=["left_to_right", "right_to_left"])
def test_held_while_the_person_would_meet_the_robot_and_let_through_when_not(path):
    """Over one period of the person's walk the robot at the band's edge is held at some times
    and let through at others; every time it is let through, driving through at the guard's
    speed keeps it clear of the person; at every time it is held, it would not have been."""
    config = PassageGuardConfig(enabled=True)
    memory = watched()
    start = hold_point(memory, path, config)
    out = verdicts(memory, path, config)
    held = [t for t, hold in out if hold]
    free = [t for t, hold in out if not hold]
    assert held and free
    for t in free:
        assert drive_through(path, start, t, config) > 0.0, f"let through at {t:.2f} s into a contact"
    # Most held times are real: the robot would have met the person (margins make a few cautious).
    met = sum(drive_through(path, start, t, config) <= 0.05 for t in held)
    assert met >= 0.6 * len(held)


def test_no_hold_without_band_or_far_from_it_or_inside_it():
    config = PassageGuardConfig(enabled=True)
    c, v = person(65.0)
    assert not check_passage(LEFT_TO_RIGHT, LEFT_TO_RIGHT[0], MoverMemory(), 65.0, c[None], v[None], np.array([PERSON]),
                             ROBOT_RADIUS, config).hold
    memory = watched()
    far = check_passage(LEFT_TO_RIGHT, LEFT_TO_RIGHT[0], memory, 65.0, c[None], v[None], np.array([PERSON]), ROBOT_RADIUS, config)
    assert not far.hold and "ahead" in far.reason
    inside = check_passage(LEFT_TO_RIGHT[3:], LEFT_TO_RIGHT[3], memory, 65.0, c[None], v[None], np.array([PERSON]),
                           ROBOT_RADIUS, config)
    assert not inside.hold and "already in the band" in inside.reason


def test_config_refuses_bad_values():
    with pytest.raises((ValueError, TypeError), match="speed"):
        PassageGuardConfig(speed=0.0)
    with pytest.raises((ValueError, TypeError), match="band_clearance"):
        PassageGuardConfig(band_clearance=-1.0)


def test_a_person_out_of_view_is_predicted_from_earlier_walks():
    """The person walked out of the scan's view (behind the middle wall, down x = 4.2) 2 s ago:
    a robot at the band's edge on the right is held while the person would come back round the
    corner into the doorway; with nobody seen for longer than ``out_of_view``, it goes."""
    config = PassageGuardConfig(enabled=True)
    memory = watched()
    start = hold_point(memory, RIGHT_TO_LEFT, config)
    t_down = 60.0 + (14.5 - (60.0 % PERIOD)) % PERIOD  # walking down x = 4.2 towards the bottom
    c, v = person(t_down)
    assert v[1] < -0.5
    seen = MoverMemory()
    for t in np.arange(t_down - 50.0, t_down, 0.1):
        ci, vi = person(float(t))
        seen.observe(float(t), ci[None], vi[None])
    none = np.zeros((0, 2))
    verdict = check_passage(RIGHT_TO_LEFT, start, seen, t_down + 2.0, none, none, np.zeros(0), ROBOT_RADIUS, config)
    assert verdict.hold and "out of view" in verdict.reason
    later = check_passage(RIGHT_TO_LEFT, start, seen, t_down + config.out_of_view + 1.0, none, none, np.zeros(0),
                          ROBOT_RADIUS, config)
    assert not later.hold and later.reason == "no mover"


@pytest.mark.parametrize("path, window", [(LEFT_TO_RIGHT, True), (RIGHT_TO_LEFT, False)], ids=["left to right", "right to left"])
def test_a_person_who_walked_out_of_view_and_back_before_is_expected_back_when_they_were(path, window):
    """The robot sees the house's person only above y = 2.9 (the walk down x = 4.2 is out of its
    view): each time the person walks out of view they come back 7.7 s later. Without what the
    memory learned of those returns the guard held the robot for as long as the person was out
    of view; with it, it lets the robot through when the person will be back too late to meet
    it (from the left room, right after the person went out of view: the robot is across their
    way and through the doorway ahead of them), and every such drive through keeps clear of the
    true walk. From the right room the drive through ends where the person comes back: held.
    Without ``returns`` it is held for as long as the person is out of view."""
    config = PassageGuardConfig(enabled=True, returns=True)

    def in_view(c: np.ndarray) -> bool:
        return bool(c[1] > 2.9)

    seen = MoverMemory()
    t_end = 120.0
    for t in np.arange(0.0, t_end, 0.1):
        c, v = person(float(t))
        if in_view(c):
            seen.observe(float(t), c[None], v[None])
    assert len(seen.returns()) >= 5  # one per walk down the leg
    start = hold_point(seen, path, config)
    none = np.zeros((0, 2))
    went, held_out_of_view, last_seen = [], 0, -np.inf
    for t in np.arange(t_end, t_end + 2 * PERIOD, 0.1):
        c, v = person(float(t))
        if in_view(c):
            seen.observe(float(t), c[None], v[None])
            last_seen = float(t)
            continue
        if t - last_seen <= 0.6:
            continue  # the scan tracker still has the person's track for a moment (OUT_OF_VIEW_AFTER)
        verdict = check_passage(path, start, seen, float(t), none, none, np.zeros(0), ROBOT_RADIUS, config)
        if verdict.hold:
            held_out_of_view += 1
            assert "out of view" in verdict.reason and "coming back" in verdict.reason, verdict.reason
        else:
            went.append(float(t))
            assert drive_through(path, start, float(t), config) > 0.0, (t, verdict.reason)
    assert held_out_of_view > 0  # the person comes back: not let through every time
    assert bool(went) == window, went
    off = attrs_evolve(config, returns=False)
    for t in np.arange(t_end + 2 * PERIOD, t_end + 3 * PERIOD, 0.5):
        c, v = person(float(t))
        if in_view(c):
            seen.observe(float(t), c[None], v[None])
        elif t - seen.samples()[-1, 0] > 0.6:
            assert check_passage(path, start, seen, float(t), none, none, np.zeros(0), ROBOT_RADIUS, off).hold


def test_the_band_survives_a_clock_going_back():
    """A restarted simulator starts its clock at 0 again: the memory keeps the band and its
    walks (moved to end just before the new time) and goes on recording."""
    memory = watched(60.0)
    before = memory.band_cells().copy()
    c, v = person(60.0)
    memory.observe(2.0, c[None], v[None])
    rows = memory.samples()
    assert rows[-1, 0] == 2.0 and rows[-2, 0] < 2.0 and len(rows) > 400
    assert len(memory.band_cells()) >= len(before)
    times = np.array([0.0, 3.0])
    assert len(memory.predict(2.0, c, v, times)) >= 2  # earlier walks still predict


def test_returns_keep_their_timing_when_the_clock_goes_back():
    memory = tracked_memory(100.0)
    before = [(b[0] - a[0], a[1:3], b[1:3]) for a, b in memory.returns()]
    c, v = tracked(100.0)
    memory.observe(2.0, c[None], v[None])  # a restarted simulator
    after = [(b[0] - a[0], a[1:3], b[1:3]) for a, b in memory.returns()]
    assert len(after) == len(before) >= 4
    assert all(abs(x[0] - y[0]) < 1e-9 and x[1:] == y[1:] for x, y in zip(before, after))
    assert all(b[0] < 2.0 for _, b in memory.returns())


def test_mover_tracking_starts_again_when_the_clock_goes_back():
    """A restarted simulator's clock starts at 0: the tracker must not ignore every scan until the
    clock catches up with the old run's last stamp."""
    from emos.actors.nav.controllers.movers import MoverWatch

    watch = MoverWatch()
    pose = np.zeros(3)
    person = np.array([[2.0, 0.0], [2.05, 0.02], [2.0, 0.05]])
    for k in range(5):
        watch.update(100.0 + 0.1 * k, person, pose)
    assert watch.stamp == pytest.approx(100.4) and watch.restarts == 0
    watch.update(100.2, person, pose)  # a little older: an out-of-order scan, ignored
    assert watch.stamp == pytest.approx(100.4) and watch.restarts == 0
    watch.update(0.5, person, pose)  # the clock went back
    assert watch.stamp == pytest.approx(0.5) and watch.restarts == 1


def test_a_short_phantom_track_does_not_replace_the_last_real_sighting():
    """The person walked out of view 1.3 s ago; since then a short track (clutter a moving
    robot's scan makes look moving, for 0.5 s, elsewhere) was the last moving track recorded: the
    guard still predicts the person from where they were really last seen, and holds."""
    config = PassageGuardConfig(enabled=True)
    memory = watched()
    start = hold_point(memory, RIGHT_TO_LEFT, config)
    t_down = 60.0 + (14.5 - (60.0 % PERIOD)) % PERIOD  # walking down x = 4.2 (as the out-of-view test)
    seen = MoverMemory()
    for t in np.arange(t_down - 50.0, t_down, 0.1):
        ci, vi = person(float(t))
        seen.observe(float(t), ci[None], vi[None])
    for t in np.arange(t_down + 0.5, t_down + 1.05, 0.1):  # the phantom: 0.5 s, 0.4 m/s, near the top-left room
        seen.observe(float(t), np.array([[1.0 + 0.4 * (t - t_down), 5.5]]), np.array([[0.4, 0.0]]))
    rows, ages = seen.last_sighting(t_down + 1.3)
    assert len(rows) == 1 and rows[0, 2] < 3.3 and abs(rows[0, 1] - 4.2) < 0.05  # the person on x = 4.2
    none = np.zeros((0, 2))
    verdict = check_passage(RIGHT_TO_LEFT, start, seen, t_down + 1.3, none, none, np.zeros(0), ROBOT_RADIUS, config)
    assert verdict.hold and "out of view" in verdict.reason and "(4.2" in verdict.reason, verdict.reason


def test_a_long_walk_is_a_real_sighting_and_a_standing_jitter_is_not():
    memory = MoverMemory()
    for k in range(40):  # 4 s of clutter jittering about one place, reported moving at 0.35 m/s
        t = 0.1 * k
        memory.observe(t, np.array([[2.0 + 0.05 * (-1) ** k, 1.0]]), np.array([[0.35, 0.0]]))
    assert len(memory.last_sighting(4.0)[0]) == 0
    for k in range(30):  # 3 s of a walk at 0.6 m/s
        t = 5.0 + 0.1 * k
        memory.observe(t, np.array([[5.0, 0.06 * k]]), np.array([[0.0, 0.6]]))
    rows, ages = memory.last_sighting(9.0)
    assert len(rows) == 1 and rows[0, 2] == pytest.approx(0.06 * 29) and ages[0] == pytest.approx(9.0 - 7.9)


def test_drive_speed_is_what_the_robot_drove_not_its_stops_turns_or_behaviors():
    from emos.actors.nav.missions.passages import DriveSpeed

    speed = DriveSpeed()
    assert speed.speed() is None and speed.start_delay() is None
    x, t = 0.0, 0.0
    for k in range(300):  # 30 s: driving at 0.2 m/s, standing 5 s (a picture), a behavior backing at 0.4 m/s
        t = 0.1 * k
        standing = 100 <= k < 150
        behavior = 200 <= k < 230
        x += 0.0 if standing else (-0.04 if behavior else 0.02)
        speed.observe(t, x, 0.0, driving=not behavior)
    assert speed.speed() == pytest.approx(0.2, abs=0.02)
    speed.released(t, x, 0.0)  # a hold ends; the robot starts 2.5 s later
    for k in range(1, 60):
        x += 0.0 if k <= 25 else 0.02
        speed.observe(t + 0.1 * k, x, 0.0)
    assert speed.start_delay() == pytest.approx(2.5 + 0.1 * 5, abs=0.15)  # 0.1 m covered 5 steps after it started
    # A hold ends and another begins 0.6 s later, before the robot moved; 3 s on a give-way
    # backs it out 0.4 m. No start of the robot's: no delay (it was timed as 4.7 s in a patrol,
    # and every later drive through was judged with it).
    t += 6.0
    speed.released(t, x, 0.0)
    for k in range(1, 60):
        held = k >= 6
        x -= 0.04 if 36 <= k < 46 else 0.0
        speed.observe(t + 0.1 * k, x, 0.0, driving=not held)
    assert speed.start_delay() == pytest.approx(2.5 + 0.1 * 5, abs=0.15)


@pytest.mark.parametrize("path", [LEFT_TO_RIGHT, RIGHT_TO_LEFT], ids=["left_to_right", "right_to_left"])
def test_the_drive_through_is_predicted_at_the_measured_speed(path):
    """A robot that drives at 0.15 m/s (a loaded machine: the nominal speed is 0.4) and is let
    through by the guard never meets the person; at the nominal speed the guard would have let it
    into a contact."""
    config = PassageGuardConfig(enabled=True)
    slow = attrs_evolve(config, speed=0.15)
    memory = watched()
    start = hold_point(memory, path, config)
    nominal_into_contact = 0
    for t in np.arange(60.0, 60.0 + PERIOD, 0.25):
        c, v = person(float(t))
        args = (path, start, memory, float(t), c[None], v[None], np.array([PERSON]), ROBOT_RADIUS, config)
        measured = check_passage(*args, measured_speed=0.15)
        if not measured.hold:
            assert drive_through(path, start, float(t), slow) > 0.0, f"let through at {t:.2f} s into a contact"
            assert "0.15 m/s" in measured.reason
        elif not check_passage(*args).hold and drive_through(path, start, float(t), slow) <= 0.0:
            nominal_into_contact += 1
    assert nominal_into_contact > 0


def attrs_evolve(config: PassageGuardConfig, **changes: float) -> PassageGuardConfig:
    import attrs

    return attrs.evolve(config, **changes)


# The scan tracker's view of the person (tests of the turn at the end of the walk and of a walk
# out of view): its velocity is a fit over the last second, so it lags the walk and passes
# through zero where the person turns round at x = 7.0 (as the tracker does in the house:
# 0.42, -0.05, -0.47 m/s a tenth of a second apart); the robot in the left room does not see
# the bottom of the walk down x = 4.2 (below y = 1.3).
def tracked(t: float) -> tuple[np.ndarray, np.ndarray]:
    return person(t)[0], person(t)[0] - person(t - 1.0)[0]


def tracked_memory(t_end: float) -> MoverMemory:
    memory = MoverMemory()
    for t in np.arange(1.0, t_end, 0.1):
        c, v = tracked(float(t))
        if c[1] > 1.3:
            memory.observe(float(t), c[None], v[None])
    return memory


def test_a_person_turning_round_at_the_end_of_their_walk_is_expected_back():
    """While the person turns round at the far end of their walk, the tracker sees them slow
    (under a walk's 0.3 m/s, moving either way): predicted as every earlier walk from there went
    on, back through the doorway, not standing where they are: the robot is held, as a drive
    through would have met the person. (It was let in at these moments before, then backed out
    by the give-way two seconds later: ten-lap patrols missed 12 of 40 waypoints so.)"""
    config = PassageGuardConfig(enabled=True)
    t_turn = 90.0 + (LENGTH / SPEED - 90.0 % PERIOD) % PERIOD  # at x = 7.0
    memory = tracked_memory(t_turn - 1.0)
    start = hold_point(memory, LEFT_TO_RIGHT, config)
    slow = 0
    for t in np.arange(t_turn - 1.0, t_turn + 1.0, 0.1):
        c, v = tracked(float(t))
        memory.observe(float(t), c[None], v[None])
        if np.hypot(*v) >= 0.3:
            continue
        slow += 1
        assert drive_through(LEFT_TO_RIGHT, start, float(t), config) <= 0.0
        verdict = check_passage(LEFT_TO_RIGHT, start, memory, float(t), c[None], v[None], np.array([PERSON]), ROBOT_RADIUS, config)
        assert verdict.hold, f"{t - t_turn:+.1f} s from the turn, tracked at {np.hypot(*v):.2f} m/s: {verdict.reason}"
    assert slow >= 3


def test_a_person_walking_out_of_view_is_expected_back_as_people_came_back_before():
    """Walking down x = 4.2 towards the bottom of their walk (out of the robot's view below
    y = 1.3): the earlier walks' records end there, and each time the person came back into view
    2.4 to 2.6 s later. Predicted on past the record as they came back (out, turning, back up the walk
    and through the doorway), not on through the wall at the last velocity: held while a drive
    through would meet them on their way back; over a whole walk there and back some moments
    still let the robot through, each clear of the person."""
    config = PassageGuardConfig(enabled=True)
    memory = tracked_memory(100.0)
    assert len(memory.returns()) >= 4
    t_down = 100.0 + (LENGTH / SPEED + 2.80 / SPEED + 1.5 - 100.0 % PERIOD) % PERIOD  # on x = 4.2, walking down
    c, v = tracked(t_down)
    assert c[1] < 2.5 and v[1] < -0.5
    times = np.arange(0.0, 8.01, 0.2)
    truth = np.array([person(t_down + dt)[0] for dt in times])
    preds = memory.predict(t_down, c, v, times)
    assert min(float(np.abs(p - truth).max()) for p in preds[1:]) < 0.35  # the learned walk, there and back
    assert np.abs(preds[0][-1] - truth[-1]).max() > 3.0  # constant velocity: through the wall
    start = hold_point(memory, LEFT_TO_RIGHT, config)
    went, held_into_contact = [], 0
    for t in np.arange(100.0, 100.0 + PERIOD, 0.2):
        c, v = tracked(float(t))
        if c[1] > 1.3:
            memory.observe(float(t), c[None], v[None])
        movers = (c[None], v[None], np.array([PERSON])) if c[1] > 1.3 else (np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))
        verdict = check_passage(LEFT_TO_RIGHT, start, memory, float(t), *movers, ROBOT_RADIUS, config)
        if verdict.start is None or verdict.start > config.approach or verdict.unseen:
            continue
        gap = drive_through(LEFT_TO_RIGHT, start, float(t), config)
        if not verdict.hold:
            went.append(float(t))
            assert gap > 0.0, f"let through at {t:.1f} s into a contact: {verdict.reason}"
        elif gap <= 0.0:
            held_into_contact += 1
    assert went and held_into_contact


def test_a_phantom_walk_does_not_take_the_place_of_where_the_person_came_back_from():
    """While the person walks down x = 4.2 out of view, the edge of the shadow they cast sweeps
    along the far room's wall, and the scan tracker sees a "mover" there for a second (in the
    house: (5.2, 2.3) to (5.4, 1.8) at 0.6 m/s, each time). It ends after the person left the
    view and before they came back: the return is the person's (from the bottom of their walk
    to where they came back up, or at the far end, where the tracker sees them slow as they turn
    round), never the phantom's."""
    memory = MoverMemory()
    phantoms = 0
    for t in np.arange(1.0, 100.0, 0.1):
        c, v = tracked(float(t))
        centres, velocities = ([c], [v]) if c[1] > 1.3 else ([], [])
        if c[0] < 4.3 and 1.4 < c[1] < 2.1 and v[1] < -0.5:  # walking down, just before leaving the view
            k = (2.1 - c[1]) / SPEED  # s since the phantom appeared
            centres.append(np.array([5.2, 2.3]) + k * np.array([0.27, -0.55]))
            velocities.append(np.array([0.27, -0.55]))
            phantoms += 1
        memory.observe(float(t), np.array(centres).reshape(-1, 2), np.array(velocities).reshape(-1, 2))
    assert phantoms > 40
    returns = memory.returns()
    assert sum(exit_[2] < 2.0 for exit_, _ in returns) >= 4  # from the bottom of the walk (and from its far end)
    def phantom(sample: tuple[float, ...]) -> bool:
        return 5.0 < sample[1] < 6.0 and sample[2] < 2.5

    for exit_, back in returns:  # the person to the person; the phantom's second is no walk to return from
        assert not phantom(exit_) and not phantom(back), f"({exit_[1]:.2f}, {exit_[2]:.2f}) -> ({back[1]:.2f}, {back[2]:.2f})"


def test_a_phantom_in_view_is_predicted_as_the_phantom_walked_not_as_the_person():
    """The robot sees the person down to y = 1.0 this time: when the phantom (above) ends, the
    person is still in view 1.3 m away, walking down. A phantom seen again where it was is
    predicted to sweep on as it did, not to have become the person (before, a record was
    continued by whatever was within 3 m/s of its last sample, and the guard held the robot for a
    phantom "predicted at (4.11, 2.46)", on the person's walk, every pass)."""
    memory = MoverMemory()
    for t in np.arange(1.0, 100.0, 0.1):
        c, v = tracked(float(t))
        centres, velocities = ([c], [v]) if c[1] > 1.0 else ([], [])
        if c[0] < 4.3 and 1.5 < c[1] < 2.2 and v[1] < -0.5:
            k = (2.2 - c[1]) / SPEED
            centres.append(np.array([5.2, 2.3]) + k * np.array([0.27, -0.55]))
            velocities.append(np.array([0.27, -0.55]))
        memory.observe(float(t), np.array(centres).reshape(-1, 2), np.array(velocities).reshape(-1, 2))
    preds = memory.predict(100.0, np.array([5.22, 2.26]), np.array([0.27, -0.55]), np.arange(0.0, 8.01, 0.2))
    assert len(preds) > 1  # earlier passes of the phantom
    for walk in preds[1:]:
        assert walk[:, 0].min() > 4.8, np.round(walk[::5], 2).tolist()


def test_a_verdict_after_a_release_judges_the_drive_the_release_began():
    """Let go when the way has been clear for ``release_time``, the robot starts after the start
    delay; a verdict while it has not moved yet judges that drive (``let_go``: the release's),
    not one a whole delay later, which held a patrol's robot again 0.3-0.6 s after its release
    on a window it had. The person as the tracker sees them, three of their walks, the
    left-to-right crossing (the right-to-left one has no window for a robot at 0.4 m/s here)."""
    config = PassageGuardConfig(enabled=True)
    memory = tracked_memory(60.0)
    start = hold_point(memory, LEFT_TO_RIGHT, config)
    clear: list[bool] = []
    releases, re_held = [], 0
    for t in np.arange(60.0, 60.0 + 3 * PERIOD, 0.1):
        c, v = tracked(float(t))
        if c[1] > 1.3:  # the bottom of the walk is out of the left room's view
            memory.observe(float(t), c[None], v[None])
        clear.append(not check_passage(LEFT_TO_RIGHT, start, memory, float(t), c[None], v[None], np.array([PERSON]),
                                       ROBOT_RADIUS, config).hold)
        if len(clear) > 11 and all(clear[-11:]) and not clear[-12]:
            releases.append(float(t))
    assert len(releases) >= 3, releases
    for t in releases:  # the same memory (the walks after a release make no difference a second later)
        assert drive_through(LEFT_TO_RIGHT, start, t, config) > 0.0
        for gone in (0.2, 0.4, 0.6, 0.8):
            c, v = tracked(t + gone)
            args = (LEFT_TO_RIGHT, start, memory, t + gone, c[None], v[None], np.array([PERSON]), ROBOT_RADIUS, config)
            re_held += check_passage(*args).hold
            verdict = check_passage(*args, let_go=gone)
            assert not verdict.hold, f"{gone} s after the release at {t:.1f} s: {verdict.reason}"
            assert f"after {config.start_delay - gone:.1f} s" in verdict.reason, verdict.reason
    assert re_held > 0  # judged as a drive a whole delay later
    c, v = tracked(60.0)
    driving = check_passage(LEFT_TO_RIGHT, start, memory, 60.0, c[None], v[None], np.array([PERSON]), ROBOT_RADIUS, config,
                            under_way=True)
    assert "after 0.0 s" in driving.reason, driving.reason
