"""Giving way to a person (issue 39, the 20-lap patrol): the yield planner
(recovery.plan_give_way), the collision-course prediction (controllers.movers.approaches), the
mover tracker's trail that the DriveManager's swept check takes as an obstacle
(controllers.movers.MoverWatch), the configuration checks, and the yielding pedestrian of the
simulator (sim.person.Person(yielding=True)) next to the blind one."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav import RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.controllers.movers import MoverWatch, approaches
from emos.actors.nav.recovery import GiveWayConfig, give_way_times, plan_give_way
from emos.actors.nav.safety import DriveSafety, SafetyZonesConfig, SweptConfig

pytestmark = pytest.mark.unit

ROBOT = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                    geometry_params=np.array([0.2, 0.3]))
PERSON = 0.22  # m, the simulator's person


def _corridor(half_width: float = 0.5, x0: float = -3.0, x1: float = 3.0) -> np.ndarray:
    xs = np.arange(x0, x1, 0.05)
    return np.r_[np.c_[xs, np.full_like(xs, half_width)], np.c_[xs, np.full_like(xs, -half_width)]]


def test_in_a_corridor_the_robot_backs_out_from_a_person_walking_at_it():
    move = plan_give_way(ROBOT, _corridor(), [[2.0, 0.0]], [[-0.6, 0.0]], [PERSON], GiveWayConfig(enabled=True))
    assert move.name == "back_out" and move.command[0] < 0.0, move


def test_a_person_crossing_far_ahead_is_waited_for_standing():
    move = plan_give_way(ROBOT, None, [[3.0, 2.0]], [[0.0, -0.6]], [PERSON], GiveWayConfig(enabled=True))
    assert move.name == "stand" and not np.any(move.command), move


def test_in_the_open_the_robot_gets_out_of_the_way_of_a_person_close_ahead():
    # No room to back out straight (a wall 0.1 m behind): it turns out of the person's line.
    wall_behind = np.c_[np.full(41, -0.3), np.linspace(-2.0, 2.0, 41)]
    cfg = GiveWayConfig(enabled=True)
    move = plan_give_way(ROBOT, wall_behind, [[2.0, 0.0]], [[-0.6, 0.0]], [PERSON], cfg, max_omega=1.0)
    assert move.name in ("pull_aside", "turn", "back_out") and move.command[2] != 0.0, move
    # Standing there would be walked into; the move keeps a gap.
    assert move.gap > 0.1


def test_the_robot_never_moves_towards_a_near_person():
    # The person is 0.3 m ahead, standing; the robot may not move forward whatever the scores say.
    for velocity in ([0.0, 0.0], [-0.6, 0.0], [0.0, 0.6]):
        move = plan_give_way(ROBOT, None, [[0.72, 0.0]], [velocity], [PERSON], GiveWayConfig(enabled=True))
        assert move.command[0] <= 0.0, (velocity, move)


def test_approaches_head_on_and_receding():
    head_on, receding = approaches([0.0, 0.0], [0.0, 0.0], 0.2, [[2.0, 0.0], [-1.0, 0.0]], [[-0.6, 0.0], [-0.6, 0.0]],
                                   [PERSON, PERSON], horizon=3.0)
    assert head_on.gap_now == pytest.approx(2.0 - 0.42) and head_on.gap_min < 0.0 and head_on.closing == pytest.approx(0.6)
    assert receding.closing == pytest.approx(-0.6) and receding.time_to_min == 0.0


def test_give_way_config_is_checked_naming_the_field():
    with pytest.raises(ValueError, match="GiveWayConfig.speed"):
        GiveWayConfig(speed=0.0)
    with pytest.raises(ValueError, match="GiveWayConfig.time_before_collision"):
        GiveWayConfig(time_before_collision=-1.0)
    with pytest.raises(ValueError, match="near_distance .* must be >= personal_space"):
        GiveWayConfig(personal_space=0.5, near_distance=0.3)
    with pytest.raises(TypeError, match="enabled"):
        GiveWayConfig(enabled="yes")  # type: ignore[arg-type]
    from emos.actors.nav.components.behaviors import BehaviorsConfig
    from emos.actors.nav.components.drive_manager import DriveManagerConfig

    assert BehaviorsConfig(give_way={"enabled": True}).give_way.enabled
    with pytest.raises(ValueError, match="GiveWayConfig.clear_time"):
        BehaviorsConfig(give_way={"clear_time": -1})
    with pytest.raises(ValueError, match="DriveManagerConfig.mover_prediction_time"):
        DriveManagerConfig(mover_prediction_time=-0.1)


def _person_scan(centre: np.ndarray, radius: float = PERSON) -> np.ndarray:
    """The visible arc of a round person seen from the origin (beam order)."""
    to = centre
    base = math.atan2(to[1], to[0])
    ang = base + math.pi + np.linspace(-1.2, 1.2, 15)
    return centre + radius * np.c_[np.cos(ang), np.sin(ang)]


def _tracked_person(watch: MoverWatch, steps: int = 12, speed: float = 0.6, start: float = 2.5) -> np.ndarray:
    """Feed scans of a person walking at the robot (at the origin, facing +x) from ``start`` m."""
    centre = np.array([start, 0.0])
    for k in range(steps):
        centre = np.array([start - speed * 0.1 * k, 0.0])
        watch.update(0.1 * k, _person_scan(centre), np.zeros(3))
    return centre


def test_the_mover_trail_extends_a_walking_person_along_its_way():
    watch = MoverWatch()
    centre = _tracked_person(watch)
    centres, velocities, _ = watch.movers()
    assert len(centres) == 1 and velocities[0, 0] == pytest.approx(-0.6, abs=0.05)
    trail = watch.trail_points(np.zeros(3), horizon=0.6)
    # The outline 0.6 s ahead: its front edge ~0.36 m nearer the robot than the person's now.
    assert trail[:, 0].min() == pytest.approx(centre[0] - 0.36 - PERSON, abs=0.05)


def test_the_swept_check_stops_the_robot_short_of_where_the_person_will_be():
    """The person 0.45 m ahead of the footprint walks at the robot at 0.6 m/s: the scan as a
    frozen picture lets a 0.3 m/s command through; with the tracked person's 0.6 s trail it is
    stopped (the robot may still back away)."""
    watch = MoverWatch()
    centre = _tracked_person(watch, steps=10, start=1.41)
    robot_front_gap = centre[0] - PERSON - 0.2
    assert robot_front_gap == pytest.approx(0.45)
    scan_pts = _person_scan(centre)
    safety = DriveSafety(ROBOT, SafetyZonesConfig(critical_zone_distance=0.05, critical_zone_angle=90.0, slowdown_zone_distance=0.3),
                         swept=SweptConfig())
    forward = np.array([0.3, 0.0, 0.0])
    frozen, _ = safety.step(forward, scan_pts, scan_pts, np.array([0.3, 0.0, 0.0]), lead=0.1)
    assert frozen[0] > 0.0
    with_trail = watch.extend(scan_pts, np.zeros(3), 1.0, 0.6)
    safety = DriveSafety(ROBOT, SafetyZonesConfig(critical_zone_distance=0.05, critical_zone_angle=90.0, slowdown_zone_distance=0.3),
                         swept=SweptConfig())
    out, _ = safety.step(forward, scan_pts, with_trail, np.array([0.3, 0.0, 0.0]), lead=0.1)
    assert out[0] < frozen[0] and out[0] < 0.1, out
    back, _ = safety.step(np.array([-0.2, 0.0, 0.0]), scan_pts, with_trail, np.zeros(3), lead=0.1)
    assert back[0] < 0.0


def test_a_trail_ends_before_the_robot_so_the_robot_can_still_back_away():
    """The person 0.1 m from the footprint walks at the robot: its trail stops short of the
    robot (keep_clear), so backing away stays allowed while driving on is cut to a creep. (A trail through
    and past the robot would stand behind it too and freeze it where the person walks into it:
    the first 20-lap run with the trail, 11 contacts in 4 laps.)"""
    watch = MoverWatch()
    centre = _tracked_person(watch, steps=10, start=1.06)
    assert centre[0] - PERSON - 0.2 == pytest.approx(0.1)
    scan_pts = _person_scan(centre)
    clear = watch.trail_points(np.zeros(3), 1.0, keep_clear=0.3)
    assert len(clear) and clear[:, 0].min() > 0.3 - 0.05
    points = np.vstack([scan_pts, clear])
    for command, least, most in (([-0.2, 0.0, 0.0], -0.2, -0.1), ([0.2, 0.0, 0.0], 0.0, 0.05)):  # (the filter ramps from rest)
        safety = DriveSafety(ROBOT, SafetyZonesConfig(critical_zone_distance=0.05, critical_zone_angle=90.0, slowdown_zone_distance=0.3),
                             swept=SweptConfig())
        out, _ = safety.step(np.array(command), scan_pts, points, np.zeros(3), lead=0.1)
        assert least - 1e-6 <= out[0] <= most + 1e-6, (command, out)


def test_a_pose_newer_than_the_scan_is_carried_back_to_it():
    from emos.actors.nav.controllers.movers import rewind

    # Turning at 1 rad/s while driving at 0.5 m/s: 0.1 s earlier it was 0.05 m back and 0.1 rad less turned.
    back = rewind(np.array([1.0, 0.0, 0.1]), np.array([0.5, 0.0, 1.0]), 0.1)
    assert back[2] == pytest.approx(0.0) and back[0] == pytest.approx(1.0 - 0.05 * math.cos(0.05), abs=1e-6)


# -- the simulator's pedestrians -------------------------------------------------------------------

def _walk(yielding: bool, seconds: float) -> tuple[float, object]:
    """A person walking along y = 0 from x = -3 to 3 at 0.6 m/s; a robot (radius 0.2) standing
    at the origin on its way. Returns the least centre distance over the walk and the person."""
    pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")
    from emos.actors.sim import SimClock, World
    from emos.actors.sim.person import Person

    world = World(clock=SimClock(mode="lockstep"))
    try:
        person = Person(waypoints=np.array([[-3.0, 0.0], [3.0, 0.0]]), speed=0.6, mode="pingpong", yielding=yielding, patience=4.0)
        world.add(person)
        world.add_robot("turtlebot3_burger", pose=(0.0, 0.0, 0.0))
        least = math.inf
        for _ in range(int(seconds / world.clock.dt)):
            world.step()
            x, y, _ = person.pose_at(world.clock.now())
            least = min(least, math.hypot(x, y))
        return least, person
    finally:
        world.close()


def test_the_blind_person_walks_through_a_standing_robot_the_yielding_one_stops_and_turns_back():
    blind, _ = _walk(False, 8.0)
    assert blind < 0.05  # it walked right through where the robot stands
    least, person = _walk(True, 12.0)
    assert least > PERSON + 0.1  # stopped short of the robot (its radius plus the clearance)
    assert person.stood > 3.0 and person.turned_back == 1  # waited, then gave up and went back


def test_a_yield_move_ends_off_the_band_where_people_walk():
    """Standing would do for a person crossing far ahead, but the robot stands in the band where
    people walked (the passage guard's memory, e.g. a person's way through a doorway): with the
    band given, the move ends out of it; without, it stands."""
    band = np.c_[np.linspace(-3.0, 3.0, 121), np.zeros(121)]  # people walked along the robot's x axis
    cfg = GiveWayConfig(enabled=True)
    stand = plan_give_way(ROBOT, None, [[3.0, 2.0]], [[0.0, -0.6]], [PERSON], cfg, max_omega=1.0)
    assert stand.name == "stand"
    off = plan_give_way(ROBOT, None, [[3.0, 2.0]], [[0.0, -0.6]], [PERSON], cfg, max_omega=1.0, band=band, band_clearance=0.55)
    assert off.name != "stand" and np.any(off.command), off


def test_a_yield_move_keeps_clear_of_where_earlier_walks_turned():
    """A person walking up behind the robot's left passes clear of it on their straight line, so
    moving on ahead looks best; but earlier walks from there turned at y = 0.3 towards +x, along
    the robot's way ahead. Given that way (``futures``, from the passage guard's memory in the
    Behaviors), the robot pulls aside off it (the patrol: a robot moved on towards the corner of
    the person's walk, and the person turned into it)."""
    cfg = GiveWayConfig(enabled=True)
    centre, velocity = np.array([-0.7, -1.5]), np.array([0.0, 0.6])
    s = 0.6 * give_way_times(cfg, 0.1)  # metres walked at the times the moves are rolled out
    up = 0.3 - centre[1]
    turned = np.where((s <= up)[:, None], centre + np.c_[np.zeros_like(s), s], np.c_[centre[0] + s - up, np.full_like(s, 0.3)])
    straight = plan_give_way(ROBOT, None, [centre], [velocity], [PERSON], cfg, max_omega=1.0)
    assert straight.name == "move_on"  # the scene: without the turn, moving on ahead is best
    aside = plan_give_way(ROBOT, None, [centre], [velocity], [PERSON], cfg, max_omega=1.0, futures=turned[None], future_radii=[PERSON])
    assert aside.name != "move_on" and aside.gap > cfg.personal_space, aside
    with pytest.raises(ValueError, match="futures"):
        plan_give_way(ROBOT, None, [centre], [velocity], [PERSON], cfg, futures=turned[None, :10], future_radii=[PERSON])
