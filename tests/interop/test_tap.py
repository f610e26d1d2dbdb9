"""TopicTap: following a run's topics from outside, new ones included, with patterns."""
from __future__ import annotations

import pytest

from emos.interop.tap import TopicTap
from emos.msgs import Int32, String, codec
from emos.transport.context import RunContext
from emos.transport.pubsub import Publisher

pytestmark = pytest.mark.unit


@pytest.fixture
def ctx():
    c = RunContext.create()
    yield c
    c.remove_everything()


def test_topics_appearing_later_are_followed_and_patterns_apply(ctx):
    early = Publisher(ctx, "/robot/odom_count", Int32, publisher_id="a")
    tap = TopicTap(ctx, topics=["/robot/*", "/chatter"], exclude=["/robot/secret"], discover_every=0.0)
    try:
        assert set(tap.subs) == {"/robot/odom_count"}
        late = Publisher(ctx, "/chatter", String, publisher_id="b")
        hidden = Publisher(ctx, "/robot/secret", String, publisher_id="c")
        other = Publisher(ctx, "/elsewhere", String, publisher_id="d")
        assert tap.discover(force=True) == ["/chatter"]  # force: same-tick creations need no wait
        late.publish(String(data="hello"))
        early.publish(Int32(data=7))
        hidden.publish(String(data="no"))
        other.publish(String(data="no"))
        got = {topic: codec.decode(tap.types[topic], frame) for topic, _stamp, frame in tap.take()}
        assert got == {"/chatter": String(data="hello"), "/robot/odom_count": Int32(data=7)}
        for p in (late, hidden, other):
            p.close()
    finally:
        tap.close()
        early.close()


def test_discovery_without_force_finds_a_topic_created_right_after_a_scan(ctx):
    tap = TopicTap(ctx, discover_every=0.0)
    try:
        pub = Publisher(ctx, "/quick", String, publisher_id="q")  # likely the same tmpfs tick as the scan
        assert tap.discover() == ["/quick"]
        pub.close()
    finally:
        tap.close()
