"""The Localizer component on the component harness (real topics, a manual clock): tracking
from ``/initialpose``, the map -> odom transform and the particle cloud, the global localization
service, and bad input through its topics (NaN / max-range / zero readings, a beam count that
contradicts the angles, a map of unknown cells only, an initial pose off the map, a 1 m
odometry jump): a log line naming the topic, no crash, the covariance grows, it recovers."""
from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from emos.actors.nav.components.convert import grid_msg
from emos.actors.nav.localization import compose_pose, noisy_odometry
from emos.msgs import LaserScan, Odometry, PoseArray, PoseWithCovarianceStamped, TFMessage
from emos.msgs.geometry import Point, Pose, PoseStamped, PoseWithCovariance, Quaternion
from emos.msgs.srv import TriggerRequest
from emos.msgs.std import Header
from emos.testing import ComponentHarness
from tests.localization.helpers import BEAMS, MAX_RANGE, cast, loop_path, room_map

pytestmark = pytest.mark.unit

NOISE = (0.01, 0.001, 0.01, 0.001)
FILTER = dict(alpha1=0.02, alpha2=0.002, alpha3=0.02, alpha4=0.002, max_beams=90, sigma_hit=0.1,
              laser_max_range=MAX_RANGE, update_min_d=0.1, update_min_a=0.1, max_particles=3000)


def _localizer(**config):
    from emos.actors.nav.components.localizer import Localizer, LocalizerConfig

    params = dict(FILTER)
    params.update(config.pop("filter_params", {}))
    return Localizer(component_name="localizer", config=LocalizerConfig(filter_params=params, seed=1, **config))


def _pose(x, y, yaw):
    return Pose(position=Point(x=float(x), y=float(y)), orientation=Quaternion.from_yaw(float(yaw)))


def _odom(p):
    msg = Odometry(header=Header(frame_id="odom"), child_frame_id="base_link")
    msg.pose.pose = _pose(*p)
    return msg


def _scan(ranges, n=None, angle_max=None):
    inc = float(BEAMS[1] - BEAMS[0])
    return LaserScan(angle_min=float(BEAMS[0]), angle_max=float(BEAMS[-1] if angle_max is None else angle_max),
                     angle_increment=inc, range_min=0.05, range_max=MAX_RANGE, ranges=np.asarray(ranges, dtype=np.float32))


def _initial(p, sd=0.05):
    cov = np.zeros(36)
    cov[0] = cov[7] = sd * sd
    cov[35] = 0.03 ** 2
    return PoseWithCovarianceStamped(header=Header(frame_id="map"), pose=PoseWithCovariance(pose=_pose(*p), covariance=cov))


def _drive(h, grid, truth, odom, scan_of=None):
    """Feed odometry then the scan at each pose; returns (position errors, covariance traces)."""
    errors, spread = [], []
    for i, (t, o) in enumerate(zip(truth, odom)):
        h.feed("/odom", _odom(o))
        h.advance(0.05)
        ranges = cast(grid, t)
        h.feed("/scan", _scan(ranges) if scan_of is None else scan_of(i, ranges))
        h.advance(0.05)
        est = h.latest("/amcl_pose")
        if est is None:
            errors.append(math.inf)
            spread.append(math.inf)
            continue
        p = est.pose.pose
        errors.append(math.hypot(p.position.x - t[0], p.position.y - t[1]))
        spread.append(float(est.pose.covariance[0] + est.pose.covariance[7]))
    return np.array(errors), np.array(spread)


def test_tracks_from_the_initial_pose_and_publishes_pose_tf_and_particles():
    grid, path = room_map(), loop_path()
    odom = noisy_odometry(path, NOISE, seed=1)
    with ComponentHarness(_localizer(max_published_particles=500)) as h:
        h.feed("/map", grid_msg(grid.data, grid.resolution, grid.origin, "map"))
        h.feed("/odom", _odom(odom[0]))
        h.feed("/scan", _scan(cast(grid, path[0])))
        h.advance(0.1)
        assert h.latest("/amcl_pose") is None and "no initial pose" in str(h.health.to_msg())
        h.feed("/initialpose", _initial(path[0]))
        errors, _ = _drive(h, grid, path, odom)
        assert np.sqrt(np.mean(errors ** 2)) < 0.05, errors.max()
        tf = h.latest("/tf")
        assert isinstance(tf, TFMessage) and tf.transforms[0].header.frame_id == "map"
        assert tf.transforms[0].child_frame_id == "odom"
        tr = tf.transforms[0].transform
        in_map = compose_pose(np.array([tr.translation.x, tr.translation.y, tr.rotation.yaw()]), odom[-1])
        assert math.hypot(*(in_map[:2] - path[-1, :2])) < 0.1, "map -> odom composed with the odometry is the pose"
        cloud = h.latest("/particle_cloud")
        assert isinstance(cloud, PoseArray) and 0 < len(cloud.poses) <= 500 and cloud.header.frame_id == "map"
        assert h.health.is_healthy


def test_global_localization_service_and_a_ui_click_as_initial_pose():
    grid, path = room_map(), loop_path()
    odom = noisy_odometry(path, NOISE, seed=2)
    cfg = dict(filter_params=dict(max_particles=20000, min_particles=1000, sigma_hit=0.2, min_ess_fraction=0.5))
    with ComponentHarness(_localizer(**cfg)) as h:
        h.feed("/map", grid_msg(grid.data, grid.resolution, grid.origin, "map"))
        h.advance(0.1)
        res = h.call("localizer/global_localization", TriggerRequest())
        assert res.success, res.message
        errors, _ = _drive(h, grid, path[:60], odom[:60])
        assert errors[-5:].max() < 0.2
    # A PoseStamped on the initial pose topic (a map click in a UI) works as well.
    from emos.io.topic import Topic

    comp = _localizer()
    comp.inputs(initial_pose=Topic(name="/goal_click", msg_type="PoseStamped"))
    with ComponentHarness(comp) as h:
        h.feed("/map", grid_msg(grid.data, grid.resolution, grid.origin, "map"))
        h.feed("/goal_click", PoseStamped(header=Header(frame_id="map"), pose=_pose(*path[0])))
        errors, _ = _drive(h, grid, path[:20], odom[:20])
        assert errors.max() < 0.1


def test_bad_scans_are_logged_by_topic_the_covariance_grows_and_it_recovers(caplog):
    grid, path = room_map(), loop_path()
    odom = noisy_odometry(path, NOISE, seed=3)

    def scans(i, r):
        if 20 <= i < 26:  # NaN, inf, zero and max-range readings among good ones
            r = r.copy()
            r[::4], r[1::4], r[2::4], r[3::8] = np.nan, np.inf, 0.0, MAX_RANGE
            return _scan(r)
        if 40 <= i < 50:  # a beam count that does not match the angles
            return _scan(r[:90])
        return _scan(r)

    with caplog.at_level(logging.WARNING), ComponentHarness(_localizer()) as h:
        h.feed("/map", grid_msg(grid.data, grid.resolution, grid.origin, "map"))
        h.feed("/initialpose", _initial(path[0]))
        errors, spread = _drive(h, grid, path, odom, scans)
        assert errors[20:26].max() < 0.2, "the valid beams of the bad scans still localize"
        assert "/scan: 90 ranges but angle_min..angle_max / angle_increment give 180 beams; scan ignored" in caplog.text
        assert spread[49] > 3 * spread[39], "odometry only while the scans are unusable: the covariance grows"
        assert errors[-20:].max() < 0.15, "good scans again: back on track"
        assert h.health.is_healthy


def test_initial_pose_off_the_map_unknown_map_and_an_odometry_jump(caplog):
    grid, path = room_map(), loop_path()
    odom = noisy_odometry(path, NOISE, seed=4)
    odom[40:, 0] += 1.0  # a 1 m wheel slip at scan 40
    cfg = dict(filter_params=dict(max_particles=5000, min_ess_fraction=0.5))
    with caplog.at_level(logging.WARNING), ComponentHarness(_localizer(**cfg)) as h:
        h.feed("/map", grid_msg(grid.data, grid.resolution, grid.origin, "map"))
        h.feed("/initialpose", _initial(path[0]))
        _drive(h, grid, path[:5], odom[:5])
        h.feed("/initialpose", _initial((25.0, -4.0, 0.0)))
        _drive(h, grid, path[5:6], odom[5:6])
        assert not h.health.is_healthy and "/initialpose" in str(h.health.to_msg())
        errors, spread = _drive(h, grid, path[6:], odom[6:])
        assert "/initialpose: initial pose (25.00, -4.00) is outside the map [0.00, 10.00] x [0.00, 8.00]; keeping the previous estimate" in caplog.text
        assert errors[:30].max() < 0.2, "the refused pose changed nothing"
        assert "/odom: odometry jumped" in caplog.text
        assert spread[34] > 5 * spread[33], "the jump spreads the cloud"
        assert errors[-20:].max() < 0.15, "and the scans find the robot again"
    caplog.clear()
    unknown = np.full_like(grid.data, -1)
    with caplog.at_level(logging.WARNING), ComponentHarness(_localizer()) as h:
        h.feed("/map", grid_msg(unknown, grid.resolution, grid.origin, "map"))
        h.feed("/initialpose", _initial(path[0]))
        errors, spread = _drive(h, grid, path[:15], path[:15])
        assert "/map: the map has no occupied cell" in caplog.text
        assert spread[-1] > spread[1] and np.isfinite(errors).all(), "the odometry alone: no crash, growing covariance"
        res = h.call("localizer/global_localization", TriggerRequest())
        assert not res.success and "no free cell" in res.message
