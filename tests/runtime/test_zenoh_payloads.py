"""The Zenoh transport's payload path in one process, over a real Zenoh session: each payload
is checked and decoded on Zenoh's thread, so a foreign, mis-typed or well-framed but
undecodable payload is dropped there with a log line naming the key (it never reaches the
reader's queue, never wakes it, never raises into it), and arrays of every size come back byte
for byte."""
import json
import logging
import os
import socket
import struct
import threading
import time
import uuid

import numpy as np
import pytest

from emos.msgs import Image, LaserScan, UInt8MultiArray, codec
from emos.transport import select
from emos.transport.netframe import FrameWriter, frame_prefix, read_frame, write_frame
from tests.runtime.helpers import shm_in_use

pytestmark = pytest.mark.unit

zenoh = pytest.importorskip("zenoh", reason="the 'net' extra (eclipse-zenoh) is not installed")
from emos.transport import zenoh_net  # noqa: E402


@pytest.fixture
def net(tmp_path):
    """A Zenoh configuration of its own (loopback, no scouting) and a fresh group."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    conf = tmp_path / "zenoh.json5"
    conf.write_text(json.dumps({
        "mode": "peer", "listen": {"endpoints": [f"tcp/127.0.0.1:{port}"]},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
    }))
    yield str(conf), f"t{uuid.uuid4().hex[:10]}"
    zenoh_net.close_sessions()


class _Wakes:
    def __init__(self):
        self.count = 0
        self.event = threading.Event()

    def __call__(self):
        self.count += 1
        self.event.set()


def _wait(cond, timeout=10.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.005)
    return False


def _warm_up(pub, sub, msg) -> None:
    """Publish until the subscriber hears (Zenoh matches the two asynchronously), then let the
    extra copies land and drop them all."""
    assert _wait(lambda: (pub.publish(msg), sub.has_news())[1]), f"no delivery on {sub.key}"
    time.sleep(0.3)
    sub.take()


def _well_framed(cls, body: bytes, publisher: str = "forger") -> bytes:
    """A frame with a correct header and ``cls``'s fingerprint around an arbitrary body."""
    fp = cls._emos_fingerprint
    prefix, start = frame_prefix(fp, publisher)
    head = b"EMZ1" + struct.pack("<QHH", 1, len(fp), len(publisher)) + prefix
    assert len(head) == start
    return head + body


@pytest.mark.parametrize("size", [8, 921_600, 8 * 1024 * 1024])
def test_arrays_of_every_size_round_trip_byte_exact_and_a_reused_frame_never_leaks(net, size):
    conf, group = net
    wakes = _Wakes()
    sub = zenoh_net.ZenohSubscriber("/blob", UInt8MultiArray, notify=wakes, queue_size=4, config_path=conf, group=group)
    pub = zenoh_net.ZenohPublisher("/blob", UInt8MultiArray, publisher_id="writer", config_path=conf, group=group)
    try:
        rng = np.random.default_rng(size)
        sent = [rng.integers(0, 256, size, dtype=np.uint8) for _ in range(3)]
        _warm_up(pub, sub, UInt8MultiArray(data=np.zeros(size, np.uint8)))
        for data in sent:  # large frames reuse one buffer: each must arrive as it was put
            pub.publish(UInt8MultiArray(data=data))
        got = []
        assert _wait(lambda: (got.extend(sub.take()), len(got) >= 3)[1]), f"got {len(got)} of 3"
        assert [m.data.tobytes() for m in got] == [d.tobytes() for d in sent]
        assert all(m.data.dtype == np.uint8 and m.data.shape == (size,) for m in got)
        assert sub.publishers() == ["writer"] and sub.rejected == 0 and wakes.count >= 4
    finally:
        pub.close()
        sub.close()


def test_small_frames_joined_equal_the_frames_written_into_a_buffer():
    img = Image(height=2, width=3, encoding="mono8", step=3, data=np.arange(6, dtype=np.uint8))
    fp = Image._emos_fingerprint
    prefix, start = frame_prefix(fp, "camera")
    joined = FrameWriter(fp, "camera").frame(codec.encode(img), 99)
    assert isinstance(joined, bytes)  # the small-frame path
    assert joined == bytes(write_frame(codec.encode(img), 99, fp, "camera", prefix, start))
    stamp, pub, payload = read_frame(joined, fp)
    assert (stamp, pub) == (99, "camera") and codec.decode(Image, payload).data.tolist() == list(range(6))


def test_foreign_mistyped_and_undecodable_payloads_are_dropped_with_a_log_naming_the_key(net, caplog):
    conf, group = net
    wakes = _Wakes()
    sub = zenoh_net.ZenohSubscriber("/scan", LaserScan, notify=wakes, config_path=conf, group=group)
    pub = zenoh_net.ZenohPublisher("/scan", LaserScan, publisher_id="lidar", config_path=conf, group=group)
    sess = zenoh_net.session(conf)
    key = zenoh_net.topic_key("/scan", group)
    other_fp = Image._emos_fingerprint
    bad = {
        "foreign bytes": b"not an emos frame at all",
        "another type": bytes(FrameWriter(other_fp, "camera").frame(codec.encode(Image(height=1, width=1, encoding="mono8", step=1, data=np.zeros(1, np.uint8))), 5)),
        "metadata longer than the frame": _well_framed(LaserScan, struct.pack("<I", 10_000) + b"\x93" * 4),
        "body that is not msgpack": _well_framed(LaserScan, struct.pack("<I", 3) + b"\xc1\xc1\xc1\0"),
        "body of the wrong shape": _well_framed(LaserScan, codec.encode(UInt8MultiArray(data=np.zeros(3, np.uint8))).to_bytes()),
    }
    try:
        caplog.set_level(logging.WARNING, logger="emos.transport.zenoh")
        _warm_up(pub, sub, LaserScan(ranges=np.ones(3, np.float32)))
        for payload in bad.values():
            sess.put(key, payload)
        pub.publish(LaserScan(ranges=np.full(5, 7.0, np.float32)))
        got = []
        assert _wait(lambda: (got.extend(sub.take()), bool(got))[1])
        # Only the real message reaches the reader; nothing was raised on either thread.
        assert len(got) == 1 and got[0].ranges.tolist() == [7.0] * 5
        assert _wait(lambda: sub.rejected == len(bad)), f"rejected {sub.rejected} of {len(bad)}"
        assert sub.undecodable == 2  # the two well-framed bodies, refused when decoded on arrival
        lines = [r.getMessage() for r in caplog.records if "dropping a payload" in r.getMessage()]
        assert lines and all(f"on key {key}" in line and "/scan" in line for line in lines)
        # The first refusal is logged; the rest within 10 s are counted into a later line.
        assert len(lines) < len(bad)
    finally:
        pub.close()
        sub.close()


def test_a_node_gets_network_messages_decoded_and_ring_payloads_decoded_as_before(net):
    conf, group = net
    wakes = _Wakes()
    sub = zenoh_net.ZenohSubscriber("/scan", LaserScan, notify=wakes, config_path=conf, group=group)
    pub = zenoh_net.ZenohPublisher("/scan", LaserScan, publisher_id="lidar", config_path=conf, group=group)
    try:
        _warm_up(pub, sub, LaserScan(ranges=np.ones(2, np.float32)))
        decode = select.payload_decoder(sub, LaserScan)
        zenoh_net.session(conf).put(sub.key, _well_framed(LaserScan, struct.pack("<I", 3) + b"\xc1\xc1\xc1\0"))
        assert _wait(lambda: sub.rejected == 1)
        assert not sub.has_news()  # the forged body was dropped on arrival: nothing to take
        pub.publish(LaserScan(ranges=np.arange(4, dtype=np.float32)))
        assert _wait(sub.has_news)
        (_, payload, publisher), = sub.take_raw()
        assert isinstance(payload, LaserScan) and publisher == "lidar"
        assert decode(payload) is payload and payload.ranges.tolist() == [0, 1, 2, 3]
    finally:
        pub.close()
        sub.close()

    class RingLike:  # a subscriber that does not decode on arrival: the shared-memory rings
        pass

    good = codec.encode(LaserScan(ranges=np.arange(4, dtype=np.float32))).to_bytes()
    plain = select.payload_decoder(RingLike(), LaserScan)
    assert plain(good).ranges.tolist() == [0, 1, 2, 3]
    with pytest.raises(codec.DecodeError):
        plain(struct.pack("<I", 3) + b"\xc1\xc1\xc1\0")


def test_an_undecodable_payload_never_displaces_the_latest_message_and_close_stops_the_wake_ups(net):
    conf, group = net
    wakes = _Wakes()
    sub = zenoh_net.ZenohSubscriber("/scan", LaserScan, notify=wakes, config_path=conf, group=group)
    pub = zenoh_net.ZenohPublisher("/scan", LaserScan, publisher_id="lidar", config_path=conf, group=group)
    sess = zenoh_net.session(conf)
    try:
        _warm_up(pub, sub, LaserScan(ranges=np.ones(2, np.float32)))
        pub.publish(LaserScan(ranges=np.full(2, 3.0, np.float32)))
        assert _wait(lambda: len(sub._queue) == 1)
        woken = wakes.count
        sess.put(zenoh_net.topic_key("/scan", group), _well_framed(LaserScan, struct.pack("<I", 3) + b"\xc1\xc1\xc1\0"))
        assert _wait(lambda: sub.rejected == 1)
        assert len(sub._queue) == 1 and wakes.count == woken  # dropped on arrival, no wake-up
        msg = sub.latest()  # the garbage came last: the latest message is still the real one
        assert msg is not None and msg.ranges.tolist() == [3.0, 3.0] and not sub.has_news()
    finally:
        pub.close()
        sub.close()
    before = wakes.count
    pub2 = zenoh_net.ZenohPublisher("/scan", LaserScan, publisher_id="late", config_path=conf, group=group)
    try:
        for _ in range(5):
            pub2.publish(LaserScan(ranges=np.ones(2, np.float32)))
        time.sleep(0.3)
        assert wakes.count == before and not sub.has_news()
    finally:
        pub2.close()


def test_a_latched_topic_replays_its_last_messages_to_late_subscribers_checked_as_live_ones(net, caplog):
    """TRANSIENT_LOCAL over Zenoh: the publisher's cache (depth) answers a subscriber that joins
    later; cached payloads of a foreign publisher on the key are dropped as live ones would be."""
    from zenoh import ext

    conf, group = net
    key = zenoh_net.topic_key("/map", group)
    pub = zenoh_net.ZenohPublisher("/map", LaserScan, publisher_id="mapper", config_path=conf, group=group, transient_local=True, depth=2)
    sess = zenoh_net.session(conf)
    foreign = ext.declare_advanced_publisher(sess, key, cache=ext.CacheConfig(2), publisher_detection=True,
                                             sample_miss_detection=ext.MissDetectionConfig(heartbeat=None, sporadic_heartbeat=None))
    subs = []
    try:
        caplog.set_level(logging.WARNING, logger="emos.transport.zenoh")
        for n in range(4):
            pub.publish(LaserScan(ranges=np.full(3, float(n), np.float32)))
        foreign.put(b"not an emos frame at all")
        foreign.put(_well_framed(LaserScan, struct.pack("<I", 3) + b"\xc1\xc1\xc1\0"))

        late = zenoh_net.ZenohSubscriber("/map", LaserScan, queue_size=4, transient_local=True, config_path=conf, group=group)
        volatile = zenoh_net.ZenohSubscriber("/map", LaserScan, queue_size=4, config_path=conf, group=group)
        subs += [late, volatile]
        got = []
        assert _wait(lambda: (got.extend(late.take()), len(got) >= 2 and late.rejected >= 2)[1]), f"got {len(got)}, rejected {late.rejected}"
        assert [m.ranges.tolist() for m in got] == [[2.0] * 3, [3.0] * 3]  # the publisher's last two, oldest first
        assert late.rejected == 2 and late.undecodable == 1 and late.publishers() == ["mapper"]  # the forger's one decodable-looking frame did not decode
        lines = [r.getMessage() for r in caplog.records if "dropping a payload" in r.getMessage()]
        assert lines and all(f"topic /map: dropping a payload on key {key}" in line for line in lines)
        assert not volatile.has_news()  # only a TRANSIENT_LOCAL subscriber asks for the past

        # Live messages follow, once each (a sample seen live and in the cache is not repeated).
        pub.publish(LaserScan(ranges=np.full(3, 4.0, np.float32)))
        assert _wait(lambda: (got.extend(late.take()), len(got) >= 3)[1])
        time.sleep(0.3)
        got.extend(late.take())
        assert [m.ranges[0] for m in got] == [2.0, 3.0, 4.0]
    finally:
        for sub in subs:
            sub.close()
        foreign.undeclare()
        pub.close()


def test_the_status_mirror_sends_every_change_and_an_unchanged_status_only_as_a_keepalive(net, ctx):
    """emos.transport.zenoh_status_mirror: a component's status ring, repeated over Zenoh."""
    from emos.msgs.status import ComponentStatus
    from emos.transport.pubsub import Publisher
    from emos.transport.zenoh_status_mirror import StatusMirror

    conf, group = net
    ring = Publisher(ctx, "/arm/status", ComponentStatus, publisher_id="arm", depth=16)
    stray = Publisher(ctx, "/arm/status", ComponentStatus, publisher_id="someone-else", depth=16)
    mirror = StatusMirror(ctx, config_path=conf, group=group, keepalive_s=60.0)
    remote = zenoh_net.ZenohSubscriber("/arm/status", ComponentStatus, queue_size=64, transient_local=True, config_path=conf, group=group)
    try:
        mirror.watch(["arm"])
        healthy = ComponentStatus(status=ComponentStatus.STATUS_HEALTHY, lifecycle_state="active", pid=7)
        failed = ComponentStatus(status=ComponentStatus.STATUS_FAILURE_ALGORITHM_LEVEL, message="no path", lifecycle_state="active", pid=7)
        seen = []
        # The first status crosses (Zenoh matches the subscriber asynchronously: repeat until it hears).
        assert _wait(lambda: (ring.publish(healthy), mirror.wait_and_forward(0.05), seen.extend(remote.take()))[2] is None and bool(seen))
        time.sleep(0.3)
        seen.extend(remote.take())
        sent = mirror.forwarded
        for status in [healthy] * 5 + [failed] + [healthy] * 5:  # a one-beat failure among unchanged beats
            ring.publish(status)
        stray.publish(failed)  # not the component's own ring: never repeated
        mirror.wait_and_forward(0.5)
        assert mirror.forwarded == sent + 2  # the failure and the recovery, not the 10 unchanged beats
        assert _wait(lambda: (seen.extend(remote.take()), seen[-1].status == ComponentStatus.STATUS_HEALTHY and len(seen) >= 3)[1])
        assert [(m.status, m.message) for m in seen[-2:]] == [(1, "no path"), (0, "")]
        assert remote.publishers() == ["arm"]

        # A reader that joins later gets the current status from the cache (depth 1).
        late = zenoh_net.ZenohSubscriber("/arm/status", ComponentStatus, transient_local=True, config_path=conf, group=group)
        try:
            got = []
            assert _wait(lambda: (got.extend(late.take()), bool(got))[1])
            assert [m.status for m in got] == [ComponentStatus.STATUS_HEALTHY]
        finally:
            late.close()
    finally:
        remote.close()
        mirror.close()
        ring.close()
        stray.close()


# ------------------------------------------------------------------------ large messages, in two parts
def test_a_large_message_travels_as_arrays_plus_a_header_and_an_array_held_in_bytes_is_not_copied():
    """FrameWriter.split: arrays of FrameWriter.SPLIT bytes or more are the sample's payload and
    the header (magic EMZ2) its attachment; an array covering a whole bytes object is sent as
    that object; several arrays, or one that is not bytes, go into the writer's reused region."""
    from emos.transport.netframe import SPLIT_MAGIC, SplitPayload

    def read_split(head, arrays, fp):  # as ZenohSubscriber reads a sample in two parts
        stamp, pub, meta = read_frame(head, fp, SPLIT_MAGIC)
        return stamp, pub, SplitPayload(meta, arrays)

    fp = UInt8MultiArray._emos_fingerprint
    writer = FrameWriter(fp, "camera")
    held = np.random.default_rng(0).integers(0, 256, FrameWriter.SPLIT, dtype=np.uint8).tobytes()
    arrays, head = writer.split(codec.encode(UInt8MultiArray(data=np.frombuffer(held, np.uint8))), 42)
    assert arrays is held and head[:4] == SPLIT_MAGIC
    stamp, pub, payload = read_split(head, arrays, fp)
    assert (stamp, pub) == (42, "camera") and isinstance(payload, SplitPayload)
    msg = payload.decode(UInt8MultiArray)
    assert msg.data.tobytes() == held and msg.data.base is held  # a view of the bytes that came

    # The decoded array is again a whole bytes object: forwarding it copies nothing either.
    assert writer.split(codec.encode(msg), 43)[0] is held
    # A slice of bytes is not the whole object: copied into the region, still exact.
    part = np.frombuffer(held, np.uint8)[8:]
    region, head = writer.split(codec.encode(UInt8MultiArray(data=part)), 44)
    assert region is not held and read_split(head, bytes(region), fp)[2].decode(UInt8MultiArray).data.tobytes() == part.tobytes()

    # Several arrays: each at its offset in the region, byte exact, and the region is reused.
    scan = LaserScan(ranges=np.linspace(0, 1, 40_000, dtype=np.float32), intensities=np.arange(40_001, dtype=np.float32))
    sfp = LaserScan._emos_fingerprint
    swriter = FrameWriter(sfp, "lidar")
    region, head = swriter.split(codec.encode(scan), 1)
    back = read_split(head, bytes(region), sfp)[2].decode(LaserScan)
    assert np.array_equal(back.ranges, scan.ranges) and np.array_equal(back.intensities, scan.intensities)
    assert swriter.split(codec.encode(scan), 2)[0] is region


def test_split_messages_cross_zenoh_a_forwarder_resends_the_received_bytes_and_bad_parts_are_dropped(net, caplog):
    conf, group = net
    key = zenoh_net.topic_key("/image", group)
    sub = zenoh_net.ZenohSubscriber("/image", Image, queue_size=16, config_path=conf, group=group)
    relay_in = zenoh_net.ZenohSubscriber("/camera", Image, queue_size=4, config_path=conf, group=group)
    camera = zenoh_net.ZenohPublisher("/camera", Image, publisher_id="camera", config_path=conf, group=group)
    relay_out = zenoh_net.ZenohPublisher("/image", Image, publisher_id="relay", config_path=conf, group=group)
    sess = zenoh_net.session(conf)
    fp = Image._emos_fingerprint
    try:
        caplog.set_level(logging.WARNING, logger="emos.transport.zenoh")
        pixels = np.random.default_rng(1).integers(0, 256, (240, 320, 3), dtype=np.uint8)
        frame = Image(height=240, width=320, encoding="rgb8", step=960, data=pixels)
        _warm_up(camera, relay_in, frame)
        _warm_up(relay_out, sub, frame)
        camera.publish(frame)
        got = []
        assert _wait(lambda: (got.extend(relay_in.take()), bool(got))[1])
        received = got[-1]
        assert isinstance(received.data.base, bytes) and len(received.data.base) == pixels.nbytes
        relay_out.publish(received)  # forwarded as the bytes that came: Zenoh's own copy only

        arrays, head = FrameWriter(fp, "forger").split(codec.encode(frame), 7)
        bad = {
            "foreign attachment": (bytes(arrays), b"not an emos header"),
            "a whole frame as the attachment": (bytes(arrays), bytes(FrameWriter(fp, "forger").frame(codec.encode(Image(data=np.zeros(1, np.uint8))), 1))),
            "a header with no array part": (head + bytes(8), None),
            "arrays shorter than the header says": (bytes(arrays)[:1000], head),
        }
        for payload, attachment in bad.values():
            sess.put(key, payload, attachment=attachment)
        relay_out.publish(Image(height=1, width=1, encoding="mono8", step=1, data=np.full(1, 9, np.uint8)))
        out = []
        assert _wait(lambda: (out.extend(sub.take()), len(out) >= 2)[1]), f"got {len(out)}"
        assert len(out) == 2 and np.array_equal(out[0].data, pixels) and out[1].data.tolist() == [9]
        assert _wait(lambda: sub.rejected == len(bad)) and sub.undecodable == 1  # the short arrays, on decode
        assert sub.publishers() == ["relay"]  # a sender counts once a message of it decodes
        lines = [r.getMessage() for r in caplog.records if "dropping a payload" in r.getMessage()]
        assert lines and all(f"on key {key}" in line for line in lines)
    finally:
        for end in (camera, relay_out, relay_in, sub):
            end.close()


def test_a_latched_large_message_replays_with_its_attachment(net):
    conf, group = net
    pub = zenoh_net.ZenohPublisher("/map", UInt8MultiArray, publisher_id="mapper", config_path=conf, group=group, transient_local=True, depth=1)
    grid = np.random.default_rng(2).integers(0, 100, 300_000, dtype=np.uint8)
    late = None
    try:
        pub.publish(UInt8MultiArray(data=grid))
        late = zenoh_net.ZenohSubscriber("/map", UInt8MultiArray, transient_local=True, config_path=conf, group=group)
        got = []
        assert _wait(lambda: (got.extend(late.take()), bool(got))[1])
        assert len(got) == 1 and np.array_equal(got[0].data, grid) and late.rejected == 0
    finally:
        if late is not None:
            late.close()
        pub.close()


# ------------------------------------------------------------------------ Zenoh's own shared memory
def test_zenoh_shared_memory_is_off_unless_the_configuration_file_mentions_it(net, tmp_path):
    """Zenoh 1.10 would carry messages of 3 KiB or more between two sessions of this host through
    shared-memory pools that receivers keep mapped for life (eclipse-zenoh/zenoh#2787): EMOS
    turns that off, so a 1 MiB exchange creates no Zenoh segment in /dev/shm; a configuration
    file that says anything about shared_memory is taken as written."""
    conf, group = net
    zen = zenoh_net._zenoh()
    assert json.loads(zenoh_net._load_config(zen, conf).get_json("transport/shared_memory/enabled")) is False
    assert json.loads(zenoh_net._load_config(zen, "").get_json("transport/shared_memory/enabled")) is False
    chosen = tmp_path / "shm.json5"
    chosen.write_text('{mode: "peer", transport: {shared_memory: {enabled: true}}}')
    assert json.loads(zenoh_net._load_config(zen, str(chosen)).get_json("transport/shared_memory/enabled")) is True

    # Two sessions of this process (two configuration files), joined over loopback TCP.
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    other = tmp_path / "other.json5"
    with open(conf) as f:
        listen = json.load(f)["listen"]["endpoints"]
    other.write_text(json.dumps({"mode": "peer", "listen": {"endpoints": [f"tcp/127.0.0.1:{port}"]}, "connect": {"endpoints": listen},
                                 "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}}}))
    # This process's segments only: other tests may be using Zenoh's shared memory beside this one.
    before = {n for n in shm_in_use(os.getpid()) if n.endswith(".zenoh")}
    sub = zenoh_net.ZenohSubscriber("/big", UInt8MultiArray, config_path=conf, group=group)
    pub = zenoh_net.ZenohPublisher("/big", UInt8MultiArray, publisher_id="far", config_path=str(other), group=group)
    try:
        data = np.random.default_rng(3).integers(0, 256, 1 << 20, dtype=np.uint8)
        got = []
        assert _wait(lambda: (pub.publish(UInt8MultiArray(data=data)), got.extend(sub.take()), bool(got))[2])
        assert np.array_equal(got[0].data, data)
        assert {n for n in shm_in_use(os.getpid()) if n.endswith(".zenoh")} - before == set()
    finally:
        pub.close()
        sub.close()


def test_declarations_wait_their_turn_while_an_admin_query_is_answered(net):
    """Zenoh 1.10 can deadlock a session when a declaration runs while another thread waits for
    an admin-space reply (a suite run hung in declare_advanced_publisher beside a SecurityWatch
    check): declaring and undeclaring take turns with those queries (zenoh_net.ROUTING_TURNS)."""
    conf, group = net
    held, release, declared = threading.Event(), threading.Event(), threading.Event()

    def admin_query() -> None:  # what SecurityWatch._admin holds while its reply is routed
        with zenoh_net.ROUTING_TURNS:
            held.set()
            release.wait(10.0)

    def declare() -> None:
        pub = zenoh_net.ZenohPublisher("/turns", UInt8MultiArray, publisher_id="w", config_path=conf, group=group,
                                       transient_local=True, depth=1)
        declared.set()
        pub.close()

    zenoh_net.session(conf)  # opened before: only the declaration waits
    query = threading.Thread(target=admin_query)
    query.start()
    assert held.wait(10.0)
    declarer = threading.Thread(target=declare)
    declarer.start()
    try:
        assert not declared.wait(0.5), "declared while an admin query held the turn"
    finally:
        release.set()
        query.join(10.0)
        declarer.join(10.0)
    assert declared.is_set()
