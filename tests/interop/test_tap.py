"""TopicTap: following a run's topics from outside, new ones included, with patterns."""
from __future__ import annotations

import shutil

import pytest

from emos.interop.tap import TopicTap
from emos.msgs import Int32, String, codec
from emos.transport.context import RunContext
from emos.transport.pubsub import Publisher, list_topics

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


def test_a_run_stopping_during_discovery_ends_it_without_an_error(ctx, tmp_path):
    """A system that stops removes its run directory (where subscribers register) while its
    rings may still be listed: the tap and the recorder must take that as the run's end, not
    as a failure (a recorder once reported it as its file's write error)."""
    from emos.interop.mcap_read import BagInfo, read_bag
    from emos.interop.record import Recorder

    first = Publisher(ctx, "/first", Int32, publisher_id="a")
    recorder = Recorder(ctx, str(tmp_path / "rec.mcap"))
    recorder.alive = lambda: True  # the watch looks once a second: the run ends between two looks
    first.publish(Int32(data=1))
    late = Publisher(ctx, "/late", String, publisher_id="b")
    shutil.rmtree(ctx.run_dir)
    try:
        assert "/late" in list_topics(ctx)
        assert recorder.tap.discover(force=True) == []
        recorder.run(should_stop=lambda: False, duration=0.3)
        assert recorder.write_error is None
    finally:
        recorder.close()
        late.close()
        first.close()
    assert recorder.failure is None
    info = BagInfo()
    assert [m.topic for m in read_bag(tmp_path / "rec.mcap", info=info)] == ["/first"]
    assert not info.truncated


def test_the_listing_skips_what_is_not_a_subscriber_folder(ctx):
    pub = Publisher(ctx, "/chatter", String, publisher_id="a")
    subs = ctx.run_dir / "subs"
    (subs / "a_file").write_text("not a folder")
    (subs / "dangling").symlink_to(subs / "nowhere")
    try:
        topics = list_topics(ctx)
        assert topics["/chatter"]["publishers"] == ["a"]
        assert "/a_file" not in topics and "/dangling" not in topics
    finally:
        pub.close()
