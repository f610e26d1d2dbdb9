import math

import numpy as np
import pytest

from emos.actors.nav.controllers.sensors import LaserScan2D
from emos.actors.nav.robot import AngularCtrlLimits, LinearCtrlLimits, RobotConfig
from emos.actors.nav.safety import (
    CommandFilter,
    CommandFilterConfig,
    SafetyZones,
    SafetyZonesConfig,
    free_travel,
    interpolate_commands,
    move_backward,
    move_forward,
    move_to_unblock,
    rotate_in_place,
    trapezoid_profile,
)

pytestmark = pytest.mark.unit


def robot(geometry="CYLINDER", params=(0.2, 0.3), model="DIFFERENTIAL_DRIVE"):
    return RobotConfig(model_type=model, geometry_type=geometry, geometry_params=np.array(params),
                       ctrl_vx_limits=LinearCtrlLimits(0.5, 1.0, 2.0),
                       ctrl_omega_limits=AngularCtrlLimits(1.0, 2.0, 4.0))


def scan_with(obstacle_angle, distance, n=360, nan_every=0):
    ang = -math.pi + np.arange(n) * 2 * math.pi / n
    ranges = np.full(n, np.inf)
    diff = np.abs((ang - obstacle_angle + math.pi) % (2 * math.pi) - math.pi)
    ranges[diff < math.radians(3)] = distance
    if nan_every:
        ranges[::nan_every] = np.nan
    return LaserScan2D(ranges, angle_min=-math.pi, angle_increment=2 * math.pi / n, range_max=10.0)


ZONES = SafetyZonesConfig(critical_zone_distance=0.1, slowdown_zone_distance=0.3, critical_zone_angle=90.0)


@pytest.mark.parametrize("geometry,params", [("CYLINDER", (0.2, 0.3)), ("BOX", (0.4, 0.4, 0.3))])
def test_zones_measure_beyond_footprint(geometry, params):
    zones = SafetyZones(robot(geometry, params), ZONES)
    # obstacle ahead 0.25 m from the centre = 0.05 m beyond a 0.2 m footprint: stop
    assert zones.check_scan(scan_with(0.0, 0.25)).emergency_stop
    # 0.4 m from the centre = 0.2 beyond: halfway through the slowdown zone
    check = zones.check_scan(scan_with(0.0, 0.4))
    assert check.factor == pytest.approx(0.5, abs=5e-3)  # beams at +-3 deg sit slightly nearer
    assert zones.check_scan(scan_with(0.0, 1.0)).factor == 1.0


def test_zones_only_look_in_the_cone_of_travel():
    zones = SafetyZones(robot(), ZONES)
    side = scan_with(math.pi / 2, 0.25)  # obstacle on the left, outside the 90 degree cone
    assert zones.check_scan(side, direction=0.0).factor == 1.0
    assert zones.check_scan(side, direction=math.pi / 2).emergency_stop  # moving left (omni)
    behind = scan_with(math.pi, 0.25)
    cmd, check = zones.limit(np.array([-0.3, 0.0, 0.2]), behind)  # reversing into it
    assert check.emergency_stop and np.allclose(cmd, 0.0)
    cmd, check = zones.limit(np.array([0.3, 0.0, 0.2]), behind)  # driving away from it
    assert np.allclose(cmd, [0.3, 0.0, 0.2])


def test_zones_slow_down_the_command_proportionally():
    zones = SafetyZones(robot(), ZONES)
    cmd, check = zones.limit(np.array([0.4, 0.0, 0.1]), scan_with(0.0, 0.4))
    np.testing.assert_allclose(cmd, [0.2, 0.0, 0.1])


def test_nan_and_inf_beams_are_not_obstacles():
    zones = SafetyZones(robot(), ZONES)
    scan = scan_with(0.0, 1.0, nan_every=2)
    assert zones.check_scan(scan).factor == 1.0
    all_bad = LaserScan2D(np.array([np.nan, np.inf] * 180), range_max=10.0)
    assert zones.check_scan(all_bad).factor == 1.0


def test_point_cloud_check_with_height_window_and_same_result_as_scan():
    cfg = SafetyZonesConfig(critical_zone_distance=0.1, slowdown_zone_distance=0.3, min_height=0.05, max_height=0.5)
    zones = SafetyZones(robot(), cfg)
    cloud = np.array([[0.25, 0.0, 1.2], [0.25, 0.0, 0.01], [0.4, 0.0, 0.2], [np.nan, 0, 0.2]])
    check = zones.check_points(cloud)
    assert check.min_distance == pytest.approx(0.2, abs=1e-6)  # only the in-window point counts
    scan = scan_with(0.0, 0.4)
    assert zones.check_points(np.stack([scan.points()[:, 0], scan.points()[:, 1]], 1)).factor == \
        pytest.approx(zones.check_scan(scan).factor, abs=1e-5)


def test_sensor_offset_is_applied():
    zones = SafetyZones(robot(), ZONES, sensor_pose=(0.1, 0.0, 0.0))
    # 0.2 m ahead of a sensor mounted 0.1 m forward = 0.3 from the centre = 0.1 beyond
    assert zones.check_scan(scan_with(0.0, 0.2)).emergency_stop


def test_config_rejects_inverted_zones():
    with pytest.raises(ValueError, match="slowdown_zone_distance"):
        SafetyZonesConfig(critical_zone_distance=0.5, slowdown_zone_distance=0.3)


def test_command_filter_separate_acc_and_decel_limits_and_velocity_clamp():
    f = CommandFilter(robot(), CommandFilterConfig(control_time_step=0.1))
    assert f([2.0, 0.0, 0.0])[0] == pytest.approx(0.1)  # max_acc 1.0 m/s^2
    f.reset([0.5, 0.0, 0.0])
    assert f([0.0, 0.0, 0.0])[0] == pytest.approx(0.3)  # max_decel 2.0 m/s^2
    f.reset([0.5, 0.0, 0.0])
    assert f([5.0, 1.0, 0.0])[1] == 0.0  # a differential robot never gets vy
    with pytest.raises(ValueError, match="finite"):
        f([np.nan, 0, 0])


def test_smoothing_lags_speeding_up_but_never_delays_braking():
    r = robot()
    smooth = CommandFilter(r, CommandFilterConfig(smooth_commands=True, smoothing_time_constant=0.3))
    raw = CommandFilter(r, CommandFilterConfig())
    smooth.reset([0.2, 0, 0])
    raw.reset([0.2, 0, 0])
    assert smooth([0.5, 0, 0])[0] < raw([0.5, 0, 0])[0]
    smooth.reset([0.4, 0, 0])
    raw.reset([0.4, 0, 0])
    assert smooth([0.0, 0, 0])[0] == pytest.approx(raw([0.0, 0, 0])[0])


def test_interpolate_commands_zero_order_hold():
    cmds = np.array([[0.1, 0, 0], [0.2, 0, 0]])
    out = interpolate_commands(cmds, 0.3, 0.1)
    np.testing.assert_allclose(out[:, 0], [0.1, 0.1, 0.1, 0.2, 0.2, 0.2])


def test_trapezoid_profile_covers_distance_within_limits():
    v = trapezoid_profile(1.0, 0.5, 1.0, 2.0, 0.1)
    assert np.sum(v) * 0.1 == pytest.approx(1.0, abs=1e-3)
    assert v.max() <= 0.5 + 1e-12
    assert np.all(np.diff(v)[: int(np.argmax(v))] <= 0.1 + 1e-9)  # acc * dt


def test_move_forward_and_backward_respect_free_space():
    r = robot()
    front_wall = scan_with(0.0, 0.5)
    fwd = move_forward(r, front_wall, max_distance=1.0, safety_margin=0.05)
    assert fwd.feasible
    travelled = np.sum(fwd.commands[:, 0]) * fwd.dt
    assert travelled == pytest.approx(0.5 - 0.2 - 0.05, abs=0.01)  # up to the margin only
    back = move_backward(r, front_wall, max_distance=0.4)
    assert back.feasible and np.sum(back.commands[:, 0]) * back.dt == pytest.approx(-0.4, abs=0.01)
    touching = scan_with(0.0, 0.22)
    assert not move_forward(r, touching).feasible


def test_rotate_in_place_needs_a_clear_circle_and_a_non_ackermann_robot():
    r = robot()
    ok = rotate_in_place(r, scan_with(0.0, 1.0), max_rotation=-math.pi / 2)
    assert ok.feasible
    assert np.sum(ok.commands[:, 2]) * ok.dt == pytest.approx(-math.pi / 2, abs=1e-3)
    assert not rotate_in_place(r, scan_with(2.0, 0.25), safety_margin=0.1).feasible
    car = robot(model="ACKERMANN")
    assert "Ackermann" in rotate_in_place(car, scan_with(0.0, 2.0)).reason


def test_move_to_unblock_picks_the_free_direction():
    r = robot()
    blocked_front = scan_with(0.0, 0.25)
    m = move_to_unblock(r, blocked_front, max_distance=0.3)
    assert m.feasible and m.name == "move_to_unblock:move_backward"
    # boxed in front and back, but room to turn
    ang = -math.pi + np.arange(360) * 2 * math.pi / 360
    ranges = np.where(np.abs(np.cos(ang)) > 0.95, 0.3, np.inf)
    boxed = LaserScan2D(ranges, angle_min=-math.pi, angle_increment=2 * math.pi / 360, range_max=10.0)
    m = move_to_unblock(r, boxed, max_distance=0.3, safety_margin=0.05)
    assert m.feasible and m.name == "move_to_unblock:rotate_in_place"
    # fully surrounded: nothing is possible, and the reason lists every attempt
    tight = LaserScan2D(np.full(360, 0.22), range_max=10.0)
    m = move_to_unblock(r, tight)
    assert not m.feasible and "move_forward" in m.reason and "rotate_in_place" in m.reason


def test_maneuvers_require_scan_data():
    with pytest.raises(ValueError, match="LaserScan"):
        move_forward(robot(), None)


def test_free_travel_box_footprint():
    box = robot("BOX", (0.6, 0.4, 0.3), model="OMNI")
    pts = np.array([[1.0, 0.15], [0.8, 0.5]])  # first is in the swept band, second beside it
    assert free_travel(box, pts, 0.0) == pytest.approx(0.7)


def test_drive_safety_pipeline_stops_at_once_slows_and_limits():
    from emos.actors.nav.safety import DriveSafety

    drive = DriveSafety(robot(), ZONES, CommandFilterConfig(control_time_step=0.1))
    free = scan_with(0.0, 5.0)
    out, check = drive.step([0.5, 0.0, 0.0], free)
    assert out[0] == pytest.approx(0.1) and check.factor == 1.0  # acceleration-limited start
    for _ in range(10):
        out, _ = drive.step([0.5, 0.0, 0.0], free)
    assert out[0] == pytest.approx(0.5)
    # slowdown zone: requested 0.5 scaled to 0.25, reached at the deceleration limit (2 m/s^2)
    out, check = drive.step([0.5, 0.0, 0.0], scan_with(0.0, 0.4 + 0.05))
    assert 0.0 < check.factor < 1.0 and out[0] == pytest.approx(max(0.5 * check.factor, 0.3))
    # obstacle in the critical zone: zero immediately, no deceleration ramp
    out, check = drive.step([0.5, 0.0, 0.0], scan_with(0.0, 0.25))
    assert check.emergency_stop and np.all(out == 0.0)
    # and the next start ramps up from rest again
    out, _ = drive.step([0.5, 0.0, 0.0], free)
    assert out[0] == pytest.approx(0.1)
    # no scan at all: do not drive blind
    out, check = drive.step([0.5, 0.0, 0.0], None)
    assert np.all(out == 0.0)
