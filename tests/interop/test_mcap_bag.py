"""MCAP recordings in-process: encodings per type, cut files, playback order, timing and looping."""
from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest

pytest.importorskip("mcap")

from mcap.reader import make_reader
from mcap.writer import Writer

from emos.interop.mcap_bag import EMOS_ENCODING, BagInfo, BagWriter, read_bag
from emos.interop.record import Player
from emos.msgs import ComponentStatus, Detections, Image, String, codec, scan_from_ranges
from emos.transport.context import RunContext
from emos.transport.pubsub import Subscriber

pytestmark = pytest.mark.unit


@pytest.fixture
def ctx():
    c = RunContext.create()
    yield c
    c.remove_everything()


def write_sample(path, n=20, chunk_size=1 << 20):
    with BagWriter(path, chunk_size=chunk_size) as w:
        for i in range(n):
            t = 1_000_000_000 + i * 50_000_000
            w.write("/camera/rgb", Image.from_numpy(np.full((20, 30, 3), i, np.uint8)), publish_ns=t)
            w.write("/scan", scan_from_ranges(np.full(8, i, np.float32)), publish_ns=t + 1)
            w.write("/detections", Detections(labels=["cup"], scores=np.array([0.5 + i / 100]), boxes=np.array([[1.0, 2, 3, 4]])), publish_ns=t + 2)
    return path


def test_shared_types_are_ros2_cdr_and_the_rest_self_described_msgpack(tmp_path):
    path = write_sample(tmp_path / "a.mcap")
    with open(path, "rb") as f:  # read with the mcap library alone: what Foxglove and ROS tools see
        summary = make_reader(f).get_summary()
    by_topic = {ch.topic: (ch, summary.schemas[ch.schema_id]) for ch in summary.channels.values()}
    ch, schema = by_topic["/scan"]
    assert (ch.message_encoding, schema.encoding, schema.name) == ("cdr", "ros2msg", "sensor_msgs/msg/LaserScan")
    assert b"MSG: std_msgs/Header" in schema.data
    ch, schema = by_topic["/detections"]
    assert ch.message_encoding == EMOS_ENCODING
    layout = json.loads(schema.data)
    assert layout["type"] == "automatika_embodied_agents/msg/Detections"
    assert [f["name"] for f in layout["fields"]] == ["header", "scores", "labels", "boxes", "image"]
    assert summary.statistics.message_count == 60

    messages = list(read_bag(path))
    assert [m.publish_ns for m in messages] == sorted(m.publish_ns for m in messages)
    dets = [m.decode() for m in messages if m.topic == "/detections"]
    assert [round(float(d.scores[0]), 2) for d in dets] == [round(0.5 + i / 100, 2) for i in range(20)]
    imgs = [m.decode() for m in messages if m.topic == "/camera/rgb"]
    assert [int(im.to_numpy()[0, 0, 0]) for im in imgs] == list(range(20))


@pytest.mark.parametrize("keep", [0.3, 0.6, 0.9])
def test_a_cut_file_reads_up_to_its_last_complete_chunk(tmp_path, keep):
    path = write_sample(tmp_path / "a.mcap", n=60, chunk_size=4096)
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * keep)])
    info = BagInfo()
    msgs = list(read_bag(cut, info=info))
    assert info.truncated and "summary" in info.truncation_detail
    assert 0 < len(msgs) <= 180  # cut in the summary section (0.9), every message survives
    if keep < 0.5:
        assert len(msgs) < 180
    # Whatever survived is intact and in order.
    imgs = [m.decode() for m in msgs if m.topic == "/camera/rgb"]
    assert [int(im.to_numpy()[0, 0, 0]) for im in imgs] == list(range(len(imgs)))


def test_channels_we_cannot_decode_say_why(tmp_path):
    path = tmp_path / "foreign.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("visualization_msgs/msg/MarkerArray", "ros2msg", b"visualization_msgs/Marker[] markers")
        c1 = w.register_channel("/markers", "cdr", sid)
        sid2 = w.register_schema("sugar/msg/ComponentStatus", "emos-msgpack-layout", json.dumps({"fingerprint": "0000"}).encode())
        c2 = w.register_channel("/x/status", EMOS_ENCODING, sid2)
        c3 = w.register_channel("/j", "json", 0)
        for c in (c1, c2, c3):
            w.add_message(c, log_time=1, publish_time=1, data=b"\x00\x01\x00\x00")
        w.finish()
    info = BagInfo()
    msgs = list(read_bag(path, info=info))
    problems = {ch.topic: ch.problem for ch in info.channels.values()}
    assert "visualization_msgs/msg/MarkerArray" in problems["/markers"]
    assert "different field layout" in problems["/x/status"]
    assert "'json'" in problems["/j"]
    with pytest.raises(LookupError, match="/markers"):
        msgs[0].decode()


def test_player_keeps_spacing_scales_time_and_loops(ctx, tmp_path):
    path = tmp_path / "strings.mcap"
    with BagWriter(path) as w:
        for i in range(10):
            w.write("/chatter", String(data=str(i)), publish_ns=5_000_000_000 + i * 40_000_000)  # 25 Hz
        w.write("/status", ComponentStatus(message="x"), publish_ns=5_000_000_000)
    sub = Subscriber(ctx, "/chatter", String, queue_size=100)
    got: list[tuple[float, str]] = []
    stop = threading.Event()

    def collect():
        while not stop.is_set():
            now = time.monotonic()
            got.extend((now, m.data) for m in sub.take())
            time.sleep(0.002)

    reader = threading.Thread(target=collect)
    reader.start()
    player = Player(ctx, str(path), rate=2.0, loop=True, topics=["chatter"])
    published = 0

    def enough() -> bool:
        return sum(player.published.values()) >= 20

    try:
        published = player.run(enough)
    finally:
        player.close(linger=0.2)
        stop.set()
        reader.join()
        sub.close()
    assert published == 20 and set(player.published) == {"/chatter"}  # /status filtered out
    assert [d for _, d in got] == [str(i % 10) for i in range(20)]
    first_pass = [t for t, _ in got[:10]]
    span = first_pass[-1] - first_pass[0]
    assert 0.12 < span < 0.5, span  # 9 gaps of 40 ms at rate 2 = 0.18 s (generous bounds: behaviour, not timing)


def test_writer_rejects_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="compression"):
        BagWriter(tmp_path / "x.mcap", compression="brotli")
    with pytest.raises(ValueError, match="rate"):
        Player(None, "x", rate=0)  # type: ignore[arg-type]


def test_frames_are_stored_byte_exact_for_our_own_types(tmp_path):
    msg = Detections(labels=["a", "b"], scores=np.array([0.1, 0.2]), boxes=np.zeros((2, 4)))
    path = tmp_path / "d.mcap"
    with BagWriter(path) as w:
        w.write("/d", msg, publish_ns=1)
    (m,) = list(read_bag(path))
    assert m.data == codec.pack(msg)


def test_player_skips_a_topic_whose_type_differs_from_the_running_systems(ctx, tmp_path):
    from emos.msgs import Int32
    from emos.transport.pubsub import Publisher

    path = tmp_path / "s.mcap"
    with BagWriter(path) as w:
        w.write("/chatter", String(data="x"), publish_ns=1)
        w.write("/other", String(data="y"), publish_ns=2)
    owner = Publisher(ctx, "/chatter", Int32, publisher_id="node")
    sub = Subscriber(ctx, "/chatter", Int32, queue_size=10)
    try:
        player = Player(ctx, str(path))
        assert player.run(lambda: False) == 1
        assert sub.take() == []  # the system's subscriber is unharmed (a wrong-type ring would make it raise)
        player.close(linger=0)
        assert "carries std_msgs/msg/Int32" in player.skipped["/chatter"]
        assert player.published == {"/other": 1}
    finally:
        sub.close()
        owner.close()


def test_a_file_written_as_rosbag2_writes_it_is_read_for_shared_types(tmp_path):
    """Bytes made by rosbags from its own ROS 2 message objects, in the layout rosbag2 uses."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    T = store.types
    ros_scan = T["sensor_msgs/msg/LaserScan"](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=3, nanosec=4), frame_id="base_scan"),
        angle_min=-1.0, angle_max=1.0, angle_increment=0.5, time_increment=0.0, scan_time=0.1, range_min=0.1,
        range_max=3.5, ranges=np.array([1, 2, 3, 4, 5], np.float32), intensities=np.array([], np.float32))
    path = tmp_path / "ros2.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="rosbag2-like")
        sid = w.register_schema("sensor_msgs/msg/LaserScan", "ros2msg", store.generate_msgdef("sensor_msgs/msg/LaserScan", ros_version=2)[0].encode())
        cid = w.register_channel("/scan", "cdr", sid, {"offered_qos_profiles": ""})
        w.add_message(cid, log_time=10, publish_time=10, data=bytes(store.serialize_cdr(ros_scan, "sensor_msgs/msg/LaserScan")))
        w.finish()
    (m,) = list(read_bag(path))
    scan = m.decode()
    assert type(scan).__name__ == "LaserScan" and scan.header.frame_id == "base_scan" and scan.header.stamp.sec == 3
    np.testing.assert_array_equal(scan.ranges, [1, 2, 3, 4, 5])


def test_foxglove_config_is_validated_at_definition():
    from emos.actors.viz import FoxgloveConfig

    with pytest.raises(ValueError, match="port must be an int in 0..65535"):
        FoxgloveConfig(port=70000)
    with pytest.raises(ValueError, match="distribution must be one of"):
        FoxgloveConfig(distribution="rolling")
    with pytest.raises(ValueError, match="list of topic names"):
        FoxgloveConfig(topics="/scan")


def test_player_skips_a_damaged_message_and_plays_on(ctx, tmp_path):
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    path = tmp_path / "damaged.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2")
        sid = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        cid = w.register_channel("/chatter", "cdr", sid)
        good = bytes(store.serialize_cdr(store.types["std_msgs/msg/String"](data="ok"), "std_msgs/msg/String"))
        for i, data in enumerate((good, b"\x00\x01\x00\x00\xff\xff\xff\x7f", good)):
            w.add_message(cid, log_time=i, publish_time=i, data=data)
        w.finish()
    sub = Subscriber(ctx, "/chatter", String, queue_size=10)
    try:
        player = Player(ctx, str(path))
        assert player.run(lambda: False) == 2
        assert [m.data for m in sub.take()] == ["ok", "ok"]  # before close: the player's ring goes with it
        player.close(linger=0)
        assert player.errors == {"/chatter": 1}
    finally:
        sub.close()
