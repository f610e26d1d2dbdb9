"""A LocalMapper that runs behind places each scan where the robot was when the scan was taken
(the odometry at the scan's stamp, as tf2 looks a transform up at a message's time), not where
the latest odometry says the robot is now; the node keeps an input's recent messages for that
(``Node.cache_input``, ROS's ``message_filters.Cache``)."""
from __future__ import annotations

import logging

import numpy as np
import pytest

from emos.actors.nav.components import LocalMapper, LocalMapperConfig
from emos.msgs import LaserScan, Odometry
from emos.msgs.geometry import Point, Pose, Quaternion
from emos.msgs.std import Header, Time
from emos.testing import ComponentHarness

pytestmark = pytest.mark.unit

SPEED = 1.0  # m/s along x: the odometry at time t is at x = SPEED * (t - start)


def _odom(t: float, x: float) -> Odometry:
    msg = Odometry(header=Header(frame_id="odom", stamp=Time.from_sec(t)), child_frame_id="base_link")
    msg.pose.pose = Pose(position=Point(x=x), orientation=Quaternion.from_yaw(0.0))
    return msg


def _scan(t: float) -> LaserScan:
    beams = np.linspace(-1.5, 1.5, 61)
    return LaserScan(header=Header(frame_id="base_link", stamp=Time.from_sec(t)), angle_min=float(beams[0]),
                     angle_max=float(beams[-1]), angle_increment=float(beams[1] - beams[0]), range_min=0.05,
                     range_max=10.0, ranges=np.full(beams.size, 2.0, dtype=np.float32))


def _mapper() -> LocalMapper:
    # A world-frame grid is placed at the pose the scan was paired with: its origin shows it.
    mapper = LocalMapper("mapper", config=LocalMapperConfig(local_map_frame="world", use_sim_time=True))
    mapper.run_type = "Event"
    return mapper


def _origin_x(h: ComponentHarness) -> float:
    grids = h.outputs("/local_map/occupancy_layer")
    assert grids, "no local map for the scan"
    return float(grids[-1].info.origin.position.x)


def _behind(h: ComponentHarness, start: float, scan_stamp: float) -> float:
    """Six odometry messages (0.02 s apart) and then a scan stamped ``scan_stamp`` arrive
    before the mapper steps: the x where it placed that scan's grid."""
    for k in range(6):
        h.feed("/odom", _odom(start + 0.02 * k, SPEED * 0.02 * k))
    h.feed("/scan", _scan(scan_stamp))
    h.step()
    return _origin_x(h)


def test_a_scan_is_placed_at_the_odometry_of_its_own_stamp():
    with ComponentHarness(_mapper(), start_time=10.0) as h:
        latest = _behind(h, 10.0, 10.10)  # the newest odometry's stamp: as before
        taken_earlier = _behind(h, 10.12, 10.12 + 0.04)  # 0.06 s behind the newest odometry
        between = _behind(h, 10.24, 10.24 + 0.05)  # halfway between two odometry messages
        newer = _behind(h, 10.36, 10.36 + 0.30)  # the odometry has not caught up: its newest
        assert h.health.is_healthy
    # Each batch restarts at x = 0; the grid's origin is the robot's x plus a fixed offset.
    offset = latest - 0.10
    assert taken_earlier - offset == pytest.approx(0.04, abs=1e-6)
    assert between - offset == pytest.approx(0.05, abs=1e-6)
    assert newer - offset == pytest.approx(0.10, abs=1e-6)


def test_a_stamp_on_another_clock_or_unset_takes_the_latest_pose_and_says_so(caplog):
    with caplog.at_level(logging.WARNING), ComponentHarness(_mapper(), start_time=100.0) as h:
        latest = _behind(h, 100.0, 100.10)
        unset = _behind(h, 100.12, 0.0)  # no stamp: nothing to look up by
        other_clock = _behind(h, 100.24, 5.0)  # 95 s older than any odometry kept
    assert unset == pytest.approx(latest, abs=1e-9) and other_clock == pytest.approx(latest, abs=1e-9)
    assert "the two clocks do not agree" in caplog.text and "/odom" in caplog.text


def test_a_cache_size_must_be_a_positive_count():
    with ComponentHarness(_mapper()) as h:
        with pytest.raises(ValueError, match=r"cache_input\('/odom'\) size must be an int >= 1, got 0"):
            h.component.node.cache_input("/odom", 0)
        assert len(h.component.node.cached("/odom")) == 0
