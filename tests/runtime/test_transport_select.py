"""The transport interface: which implementation a topic gets, and the network frame's reader
against malformed input."""
import os
import struct

import numpy as np
import pytest

from emos import Topic
from emos.msgs import Image, LaserScan, codec
from emos.transport import select
from emos.transport.netframe import BadFrame, frame_prefix, read_frame, write_frame
from emos.transport.pubsub import Publisher, Subscriber

pytestmark = pytest.mark.unit


def _frame(msg, publisher="cam", stamp=42):
    fp = type(msg)._emos_fingerprint
    prefix, start = frame_prefix(fp, publisher)
    return bytes(write_frame(codec.encode(msg), stamp, fp, publisher, prefix, start))


def test_a_frame_round_trips_with_its_arrays_aligned_and_a_reused_buffer():
    img = Image(height=2, width=3, encoding="mono8", step=3, data=np.arange(6, dtype=np.uint8))
    fp = Image._emos_fingerprint
    prefix, start = frame_prefix(fp, "camera")
    first = write_frame(codec.encode(img), 7, fp, "camera", prefix, start)
    second = write_frame(codec.encode(img), 8, fp, "camera", prefix, start, reuse=first)
    assert second is first  # same size: the buffer is reused
    stamp, pub, payload = read_frame(bytes(second), fp)
    assert (stamp, pub) == (8, "camera")
    back = codec.decode(Image, payload)
    assert back.width == 3 and back.data.tolist() == list(range(6))


@pytest.mark.parametrize("mangle, reason", [
    (lambda f: f[:10], "shorter than a frame header"),
    (lambda f: b"XXXX" + f[4:], "not an EMOS frame"),
    (lambda f: f[:12] + struct.pack("<HH", 60000, 3) + f[16:], "exceed"),
    (lambda f: f[:12] + struct.pack("<HH", 900, 900) + f[16:40], "announces"),
    (lambda f: f[:32] + b"\xff\xfe\xfd" + f[35:], "UTF-8"),  # the publisher name "cam"
    (lambda f: f[:16] + b"\xff" * 16 + f[32:], "type fingerprint"),
])
def test_malformed_frames_are_refused_with_the_reason(mangle, reason):
    frame = _frame(LaserScan(ranges=np.ones(4, dtype=np.float32)))
    with pytest.raises(BadFrame, match=reason):
        read_frame(mangle(frame), LaserScan._emos_fingerprint)


def test_a_publishers_names_checked_once_do_not_let_a_differently_split_frame_through():
    frame = _frame(LaserScan(ranges=np.ones(4, dtype=np.float32)), publisher="lidar")
    fp = LaserScan._emos_fingerprint
    assert read_frame(frame, fp)[1] == "lidar" and read_frame(frame, fp)[1] == "lidar"  # the second from the cache
    fp_len = len(fp.encode())
    resplit = frame[:12] + struct.pack("<HH", fp_len - 1, len("lidar") + 1) + frame[16:]  # same bytes, other lengths
    with pytest.raises(BadFrame, match="type fingerprint"):
        read_frame(resplit, fp)
    with pytest.raises(BadFrame, match="type fingerprint"):
        read_frame(frame, Image._emos_fingerprint)  # cached for LaserScan only


def test_a_frame_of_another_type_is_refused_naming_both():
    frame = _frame(LaserScan(ranges=np.ones(4, dtype=np.float32)), publisher="lidar")
    with pytest.raises(BadFrame, match=r"'lidar' sends type fingerprint"):
        read_frame(frame, Image._emos_fingerprint)


def test_random_bytes_never_escape_as_anything_but_bad_frame_or_decode_error():
    rng = np.random.default_rng(1)
    good = _frame(LaserScan(ranges=np.ones(16, dtype=np.float32)))
    for i in range(300):
        data = bytearray(good)
        for pos in rng.integers(0, len(data), size=1 + i % 8):
            data[pos] = int(rng.integers(0, 256))
        try:
            _, _, payload = read_frame(bytes(data), LaserScan._emos_fingerprint)
            codec.decode(LaserScan, payload)
        except (BadFrame, codec.DecodeError):
            pass


def test_transport_choice_per_topic_and_per_run(monkeypatch):
    monkeypatch.delenv(select.ENV_NET_TOPICS, raising=False)
    assert select.transport_of("/scan") == "shm"
    assert select.transport_of("/scan", "zenoh") == "zenoh"
    monkeypatch.setenv(select.ENV_NET_TOPICS, "scan, /camera/rgb")
    assert [select.transport_of(t) for t in ("/scan", "/camera/rgb", "/odom")] == ["zenoh", "zenoh", "shm"]
    assert select.transport_of("/scan", "shm") == "shm"  # pinned local in the recipe
    monkeypatch.setenv(select.ENV_NET_TOPICS, "all")
    assert select.transport_of("/odom") == "zenoh"
    monkeypatch.setenv(select.ENV_NET_TOPICS, "bad//name")
    with pytest.raises(ValueError, match="EMOS_NET_TOPICS"):
        select.transport_of("/odom")


def test_topic_transport_is_validated_at_definition_and_kept_in_its_dict():
    with pytest.raises(ValueError, match=r"Topic '/scan': transport must be one of"):
        Topic(name="scan", msg_type="LaserScan", transport="udp")
    t = Topic(name="scan", msg_type="LaserScan", transport="zenoh")
    assert Topic.from_dict(t.to_dict()).transport == "zenoh"
    assert "transport" not in Topic(name="scan", msg_type="LaserScan").to_dict()


def test_local_topics_get_the_shared_memory_classes_themselves(ctx, monkeypatch):
    monkeypatch.delenv(select.ENV_NET_TOPICS, raising=False)
    topic = Topic(name="sel_scan", msg_type="LaserScan")
    pub = select.open_publisher(ctx, topic, publisher_id="p")
    sub = select.open_subscriber(ctx, topic)
    try:
        assert type(pub) is Publisher and type(sub) is Subscriber  # unwrapped: no added cost
        pub.publish(LaserScan(ranges=np.ones(3, dtype=np.float32)))
        assert len(sub.take_raw()) == 1 and sub.writer_pids() == [os.getpid()]
        assert select.list_topics(ctx, network=False)["/sel_scan"]["transport"] == "shm"
    finally:
        sub.close()
        pub.close()


def test_use_network_sets_the_run_options_and_checks_them(tmp_path, monkeypatch):
    import emos

    for var in (select.ENV_NET_TOPICS, select.ENV_NET_SERVICES, "EMOS_ZENOH_CONFIG", "EMOS_NET_GROUP"):
        # setenv first so monkeypatch records the variable and removes what use_network sets: a
        # bare delenv of an absent variable records nothing, and EMOS_NET_TOPICS=/scan leaked into
        # every later test (their Simulators then sent /scan over Zenoh only).
        monkeypatch.setenv(var, "")
        monkeypatch.delenv(var)
    conf = tmp_path / "z.json5"
    conf.write_text("{}")
    emos.use_network(zenoh_config=str(conf), topics=["/scan", "camera/rgb"], services="all", group="lab-1")
    assert os.environ["EMOS_ZENOH_CONFIG"] == str(conf) and os.environ["EMOS_NET_GROUP"] == "lab-1"
    assert select.transport_of("/camera/rgb") == "zenoh" and select.transport_of("/odom") == "shm"
    assert os.environ[select.ENV_NET_SERVICES] == "all"
    with pytest.raises(FileNotFoundError, match="nowhere.json5"):
        emos.use_network(zenoh_config=str(tmp_path / "nowhere.json5"))
    with pytest.raises(ValueError, match="group"):
        emos.use_network(group="has space")
    assert os.environ["EMOS_NET_GROUP"] == "lab-1"
    with pytest.raises(ValueError, match="EMOS_NET_TOPICS"):
        emos.use_network(topics=["bad//name"])
    assert select.transport_of("/scan") == "zenoh"  # the earlier choice stands


def test_the_monitor_reads_its_own_runs_statuses_from_rings_and_other_runs_over_zenoh(monkeypatch, caplog):
    """Where the Monitor's component status inputs come from (emos.supervisor.monitor_net)."""
    from emos.config.qos import TRANSIENT_LOCAL
    from emos.supervisor.monitor_net import place_inputs

    topics = {t.name: t for t in (
        Topic(name="planner/status", msg_type="ComponentStatus"),  # this run's
        Topic(name="remote/arm/status", msg_type="ComponentStatus"),  # another run's
        Topic(name="scan", msg_type="LaserScan"),  # not a status: as declared
        Topic(name="odd/status", msg_type="String"),  # named like one, but not a status
    )}
    for var in ("EMOS_ZENOH_CONFIG", "EMOS_NET_TOPICS"):
        monkeypatch.delenv(var, raising=False)
    placed = place_inputs(topics, ["planner"])
    assert placed["/planner/status"].transport == "shm" and placed["/scan"].transport == "auto"
    assert placed["/remote/arm/status"].transport == "auto"  # no Zenoh in this run: warned, never arrives
    assert "'remote/arm' is not a component of this run and the run does not use Zenoh" in caplog.text

    monkeypatch.setenv("EMOS_NET_TOPICS", "all")
    placed = place_inputs(topics, ["planner"])
    assert placed["/planner/status"].transport == "shm"  # published on its ring only, whatever the option
    remote = placed["/remote/arm/status"]
    assert remote.transport == "zenoh" and remote.qos_profile.durability == TRANSIENT_LOCAL
    assert placed["/scan"] is topics["/scan"] and placed["/odd/status"] is topics["/odd/status"]
    assert topics["/remote/arm/status"].transport == "auto"  # the recipe's topics are not changed

    monkeypatch.delenv("EMOS_NET_TOPICS")
    monkeypatch.setenv("EMOS_ZENOH_CONFIG", "/some/zenoh.json5")  # --zenoh alone is enough for other runs' statuses
    assert place_inputs(topics, ["planner"])["/remote/arm/status"].transport == "zenoh"
