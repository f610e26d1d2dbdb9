"""The Mapper component on the component harness (real topics, a manual clock): it maps a room
from scans and drifting odometry, publishes the map (TRANSIENT_LOCAL /map) and map -> odom,
saves the map through its service, and survives bad scans with a log line naming the topic."""
from __future__ import annotations

import logging
import math

import numpy as np
import pytest

pytest.importorskip("gtsam")

from emos.actors.nav.components.interfaces import SaveMapRequest
from emos.actors.nav.localization import compose_pose, noisy_odometry
from emos.actors.nav.maps import load_map
from emos.msgs import LaserScan, Odometry, TFMessage
from emos.msgs.geometry import Point, Pose, Quaternion
from emos.msgs.std import Header
from emos.testing import ComponentHarness
from tests.localization.helpers import BEAMS, MAX_RANGE, cast, loop_path, room_map

pytestmark = pytest.mark.unit


def _mapper(**config):
    from emos.actors.nav.components.mapper import Mapper, MapperConfig

    slam = dict(max_range=MAX_RANGE - 0.01, odom_alphas=(0.02, 0.002, 0.02, 0.002))
    return Mapper(component_name="mapper", config=MapperConfig(slam_params=slam, update_min_d=0.1, update_min_a=0.1,
                                                               map_period=2.0, **config))


def _odom(p):
    msg = Odometry(header=Header(frame_id="odom"), child_frame_id="base_link")
    msg.pose.pose = Pose(position=Point(x=float(p[0]), y=float(p[1])), orientation=Quaternion.from_yaw(float(p[2])))
    return msg


def _scan(ranges, angle_max=None):
    inc = float(BEAMS[1] - BEAMS[0])
    return LaserScan(angle_min=float(BEAMS[0]), angle_max=float(BEAMS[-1] if angle_max is None else angle_max),
                     angle_increment=inc, range_min=0.05, range_max=MAX_RANGE, ranges=np.asarray(ranges, dtype=np.float32))


def test_maps_a_room_publishes_map_and_tf_and_saves(tmp_path, caplog):
    grid, path = room_map(), loop_path(80)
    odom = noisy_odometry(path, (0.01, 0.001, 0.01, 0.001), seed=1)
    with caplog.at_level(logging.WARNING), ComponentHarness(_mapper()) as h:
        for i, (t, o) in enumerate(zip(path, odom)):
            h.feed("/odom", _odom(o))
            h.advance(0.05)
            ranges = cast(grid, t)
            if i == 20:
                ranges = ranges.copy()
                ranges[::5], ranges[1::5], ranges[2::5] = np.nan, np.inf, 0.0  # bad readings
                h.feed("/scan", _scan(ranges))
            elif i == 30:
                h.feed("/scan", _scan(ranges[:-7]))  # beam count contradicts the angles
            else:
                h.feed("/scan", _scan(ranges))
            h.advance(0.05)
        tf = h.latest("/tf")
        assert isinstance(tf, TFMessage) and tf.transforms[0].header.frame_id == "map"
        assert tf.transforms[0].child_frame_id == "odom"
        tr = tf.transforms[0].transform
        in_map = compose_pose(np.array([tr.translation.x, tr.translation.y, tr.rotation.yaw()]), odom[-1])
        # The map frame starts at the first odometry pose, which is the path's first pose.
        assert math.hypot(*(in_map[:2] - path[-1, :2])) < 0.1
        assert math.hypot(*(odom[-1, :2] - path[-1, :2])) > 0.1, "the odometry alone drifted"
        m = h.latest("/map")
        assert m is not None and m.header.frame_id == "map" and int(m.info.width) > 100
        resp = h.call("mapper/save_map", SaveMapRequest(file_location=str(tmp_path), file_name="office"))
        assert resp.success, resp.message
        saved = load_map(tmp_path / "office.yaml")
        assert (saved.data == 100).sum() > 200 and (saved.data == 0).sum() > 1000
        assert h.health.is_healthy
    # The SLAM's log lines name the component and the topic.
    assert "mapper (/scan): scan" in caplog.text and "ranges for 180 beam angles" in caplog.text
    assert "NaN/inf" in caplog.text
