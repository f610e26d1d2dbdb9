"""The QoS mapping's pure parts and the bridge's run options (no ROS 2 needed)."""
from __future__ import annotations

import pytest

from emos.config.qos import BEST_EFFORT, TRANSIENT_LOCAL, QoSConfig
from emos.interop.ros2 import qos as Q
from emos.interop.ros2.options import check_domain, parse_topics

pytestmark = pytest.mark.unit


def test_profiles_and_defaults_follow_ros2_conventions():
    assert Q.as_qos("sensor_data") == QoSConfig(queue_size=5, reliability=BEST_EFFORT)
    assert Q.as_qos("latched") == QoSConfig(queue_size=1, durability=TRANSIENT_LOCAL)
    assert Q.as_qos({"queue_size": 3, "durability": "TRANSIENT_LOCAL"}).transient_local
    assert Q.default_for("/map").transient_local and Q.default_for("/robot1/map").transient_local
    assert Q.default_for("/tf_static").transient_local and not Q.default_for("/scan").transient_local
    assert Q.describe(Q.default_for("/scan")) == "RELIABLE/VOLATILE/depth 10"


@pytest.mark.parametrize("bad", ["sensor", 3, {"queue_size": 0}, {"nope": 1}])
def test_a_bad_qos_is_refused_naming_the_topic(bad):
    with pytest.raises(ValueError, match=r"qos\['/scan'\]"):
        Q.as_qos(bad, "qos['/scan']")


def test_topic_options():
    assert parse_topics("all") == [] and parse_topics(None) == [] and parse_topics(["all"]) == []
    assert parse_topics("scan, /cmd_vel,camera/*") == ["/scan", "/cmd_vel", "/camera/*"]
    with pytest.raises(ValueError, match="~scan"):
        parse_topics("~scan")
    assert check_domain(None) is None and check_domain(0) == 0 and check_domain(101) == 101
    for bad in (-1, 233, 1.5, True, "3"):
        with pytest.raises(ValueError, match="0..232"):
            check_domain(bad)
