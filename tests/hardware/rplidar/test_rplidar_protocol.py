"""RPLIDAR protocol codec and stream parser, against the clauses of Slamtec's protocol document
(cited in actors/hardware/rplidar/protocol.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.hardware.rplidar import protocol as P
from emos.actors.hardware.rplidar.scan import RevolutionAssembler, RevolutionStream, revolution_ranges

pytestmark = pytest.mark.unit


def _nodes(n: int, rng: np.random.Generator, revs: int = 1):
    per = n // revs
    start = (np.arange(n) % per) == 0
    quality = rng.integers(0, 64, n)
    angle = (np.arange(n) % per) * (P.ANGLE_Q6_FULL // per) + rng.integers(0, 10, n)
    dist = rng.integers(0, 0x10000, n)
    return start, quality, angle, dist


def test_requests_match_the_document_bytes():
    # §2 Fig. 2-4 and the §4 request packets
    assert P.request(P.CMD_STOP) == bytes.fromhex("a525")
    assert P.request(P.CMD_RESET) == bytes.fromhex("a540")
    assert P.request(P.CMD_SCAN) == bytes.fromhex("a520")
    assert P.request(P.CMD_GET_INFO) == bytes.fromhex("a550")
    assert P.request(P.CMD_GET_HEALTH) == bytes.fromhex("a552")
    # SET_MOTOR_PWM 660 = 0x0294: A5 F0 02 94 02, checksum = A5^F0^02^94^02
    pkt = P.motor_pwm_request(660)
    assert pkt[:5] == bytes.fromhex("a5f0029402")
    assert pkt[5] == 0xA5 ^ 0xF0 ^ 0x02 ^ 0x94 ^ 0x02
    assert P.checksum(pkt) == 0  # XOR over a packet with its checksum is zero
    with pytest.raises(P.RplidarProtocolError, match="0..1023"):
        P.motor_pwm_request(1024)


def test_descriptors_match_the_document_bytes_and_round_trip():
    assert P.SCAN_DESCRIPTOR.encode() == bytes.fromhex("a55a0500004081")  # Fig. 4-4
    assert P.INFO_DESCRIPTOR.encode() == bytes.fromhex("a55a1400000004")  # Fig. 4-16
    assert P.HEALTH_DESCRIPTOR.encode() == bytes.fromhex("a55a0300000006")  # Fig. 4-19
    for d in (P.SCAN_DESCRIPTOR, P.INFO_DESCRIPTOR, P.Descriptor(0x3FFFFFFF, 3, 0xFF)):
        assert P.Descriptor.decode(d.encode()) == d
    with pytest.raises(P.RplidarProtocolError, match="A5 5A"):
        P.Descriptor.decode(bytes.fromhex("a55b0500004081"))
    assert P.find_descriptor(b"RP LIDAR System.\r\n" + P.SCAN_DESCRIPTOR.encode(), P.SCAN_DESCRIPTOR) == 18


def test_health_is_little_endian_and_info_round_trips():
    # Fig. 4-19: status, error_code[7:0], error_code[15:8]
    assert P.Health.decode(bytes((2, 0x34, 0x12))) == P.Health(2, 0x1234)
    assert P.Health(1, 0xBEEF).encode() == bytes((1, 0xEF, 0xBE))
    info = P.DeviceInfo(0x18, 29, 1, 7, bytes(range(16)))
    assert P.DeviceInfo.decode(info.encode()) == info and info.firmware == "1.29"


def test_nodes_round_trip_and_carry_the_check_bits():
    rng = np.random.default_rng(1)
    start, q, a, d = _nodes(1000, rng, revs=3)
    raw = P.encode_nodes(start, q, a, d)
    rows = np.frombuffer(raw, np.uint8).reshape(-1, 5)
    assert ((rows[:, 0] & 1) ^ ((rows[:, 0] >> 1) & 1)).all()  # S-bar = !S
    assert (rows[:, 1] & 1).all()  # C = 1
    back = P.decode_nodes(raw)
    assert (back.start == start).all() and (back.quality == q).all()
    assert (back.angle_q6 == a).all() and (back.distance_q2 == d).all()
    # Fig. 4-5 example: angle_q6 / 64 degrees, distance_q2 / 4 mm
    one = P.decode_nodes(P.encode_nodes([True], [15], [90 * 64], [1000 * 4]))
    assert one.angle_deg[0] == 90.0 and one.distance_mm[0] == 1000.0


@pytest.mark.parametrize("chunk", [1, 3, 7, 4096])
def test_parser_in_sync_any_chunking_yields_every_node_and_drops_nothing(chunk):
    rng = np.random.default_rng(2)
    start, q, a, d = _nodes(720, rng, revs=2)
    raw = P.encode_nodes(start, q, a, d)
    parser = P.NodeParser()
    got = P.Nodes.concat([parser.feed(raw[i:i + chunk]) for i in range(0, len(raw), chunk)])
    # the last two nodes wait for successors (the in-sync rule), every other one is out
    assert len(got) == 718 and parser.dropped == 0 and parser.resyncs == 0 and len(parser._buf) == 10
    assert (got.angle_q6 == a[:718]).all() and (got.distance_q2 == d[:718]).all()


def _is_subsequence(got: P.Nodes, truth: P.Nodes) -> bool:
    key_t = list(zip(truth.start.tolist(), truth.quality.tolist(), truth.angle_q6.tolist(), truth.distance_q2.tolist()))
    key_g = zip(got.start.tolist(), got.quality.tolist(), got.angle_q6.tolist(), got.distance_q2.tolist())
    it = iter(key_t)
    return all(any(k == t for t in it) for k in key_g)


def test_parser_resyncs_after_garbage_counts_every_dropped_byte_and_never_yields_a_corrupt_node():
    rng = np.random.default_rng(3)
    start, q, a, d = _nodes(3600, rng, revs=10)
    raw = P.encode_nodes(start, q, a, d)
    truth = P.decode_nodes(raw)
    # garbage (random lengths, not multiples of 5) at 40 random node boundaries and mid-node
    cuts = sorted(rng.choice(np.arange(1, len(raw)), 40, replace=False).tolist())
    pieces, prev, garbage = [], 0, 0
    for c in cuts:
        g = rng.integers(0, 256, int(rng.integers(1, 30))).astype(np.uint8).tobytes()
        pieces += [raw[prev:c], g]
        garbage += len(g)
        prev = c
    pieces.append(raw[prev:])
    stream = b"".join(pieces)
    parser = P.NodeParser()
    got = P.Nodes.concat([parser.feed(stream[i:i + 61]) for i in range(0, len(stream), 61)])
    assert _is_subsequence(got, truth), "a node that was never sent came out"
    # every byte in is a node out, dropped, or still buffered (a partial node at the end)
    assert len(got) * 5 + parser.dropped + len(parser._buf) == len(stream)
    assert parser.dropped >= garbage and parser.resyncs >= 1
    assert len(got) > 3600 - 40 * 6  # at most a few nodes around each insertion are lost


def test_parser_truncated_node_is_held_then_dropped_on_resync():
    raw = P.encode_nodes([True, False, False, False, False], [10] * 5, [0, 64, 128, 192, 256], [4000] * 5)
    parser = P.NodeParser()
    assert len(parser.feed(raw[:12])) == 0  # 2.4 nodes: not yet confirmed
    got = parser.feed(raw[12:15])  # the third node completes: locked; the last two wait for successors
    assert len(got) == 1 and parser.dropped == 0
    # a node cut short (2 of its 5 bytes lost on the line), then the stream goes on
    more = P.encode_nodes([False] * 6, [10] * 6, [320, 384, 448, 512, 576, 640], [4000] * 6)
    out = parser.feed(raw[15:18] + more)  # node 3 truncated to 3 bytes
    assert parser.dropped >= 3 and parser.resyncs == 1
    # the truncated node (angle 192) passes its own checks but is never delivered
    # 128 and the truncated 192 are the suspects before the failure, 320 opened the new lock,
    # 576 and 640 wait for successors; 64 (held before) was good
    assert out.angle_q6.tolist() == [64, 384, 448, 512]


def test_parser_rejects_the_out_of_sync_stream_pyrplidar_would_accept():
    """Shifted by 2 bytes the stream is out of sync: a reader that reads 5 bytes at a time
    without the S/S-bar/C checks (pyrplidar's PyRPlidarMeasurement) decodes garbage nodes; the
    document's check bits (Fig. 4-5) reject every one of them and the parser re-locks."""
    raw = P.encode_nodes([i == 0 for i in range(50)], [20] * 50, [i * 460 for i in range(50)], [8000] * 50)
    shifted = raw[2:]
    parser = P.NodeParser()
    got = parser.feed(shifted)
    assert _is_subsequence(got, P.decode_nodes(raw)) and len(got) == 46 and parser.dropped == 3 + 5


def test_revolutions_cut_on_start_flag_and_dirty_ones_are_marked():
    n = 360
    start = (np.arange(3 * n + 10) % n) == 0
    start[:5] = False  # a partial revolution before the first S: discarded
    nodes = P.Nodes(start, np.full(len(start), 30, np.uint8), ((np.arange(len(start)) % n) * 64).astype(np.uint16),
                    np.full(len(start), 8000, np.uint16))
    asm = RevolutionAssembler()
    revs = asm.feed(nodes)
    assert [len(r.nodes) for r in revs] == [n, n] and all(r.clean for r in revs)
    asm.mark_dirty()
    tail = P.Nodes(np.array([True]), np.array([1], np.uint8), np.array([0], np.uint16), np.array([4], np.uint16))
    (last,) = asm.feed(tail)
    assert not last.clean and len(last.nodes) == 10


def test_clockwise_angles_become_ros_counter_clockwise_bearings():
    # Fig. 4-6: 90 deg clockwise = the lidar's right = ROS bearing -pi/2
    nodes = P.Nodes(np.array([True, False, False]), np.array([40, 40, 40], np.uint8),
                    np.array([0, 90 * 64, 270 * 64], np.uint16), np.array([4000, 8000, 12000], np.uint16))
    ranges, inten = revolution_ranges(nodes, 360, 0.15, 12.0)
    bearing = -math.pi + np.arange(360) * (2 * math.pi / 360)
    hits = {round(math.degrees(bearing[i])): float(ranges[i]) for i in np.flatnonzero(np.isfinite(ranges))}
    assert hits == {0: 1.0, -90: 2.0, 90: 3.0}
    assert inten[np.isfinite(ranges)].tolist() == [40.0, 40.0, 40.0]
    # distance 0 = invalid (Fig. 4-5) -> no return
    zero = P.Nodes(np.array([True]), np.array([0], np.uint8), np.array([0], np.uint16), np.array([0], np.uint16))
    assert not np.isfinite(revolution_ranges(zero, 360, 0.15, 12.0)[0]).any()


def _slipped_stream(seed: int, n: int = 3600, slips: int = 25):
    """A rotation-ordered stream (as a lidar sends it) with random slips: garbage, lost bytes,
    repeated bytes. Net slips of a multiple of 5 bytes are left out: they realign the stream
    and, inside a node's distance bytes (which carry no check bit), no rule of the protocol
    can see them; so are two slips within 20 nodes, which can add up to one."""
    rng = np.random.default_rng(100 + seed)
    per = 360
    start = (np.arange(n) % per) == 0
    angle = ((np.arange(n) % per) * 64 + rng.integers(0, 40, n)).clip(0, P.ANGLE_Q6_FULL - 1)
    raw = P.encode_nodes(start, rng.integers(0, 64, n), angle, rng.integers(0, 0x10000, n))
    out, prev = [], 0
    for c in sorted(rng.choice(np.arange(10, len(raw) - 40), slips, replace=False).tolist()):
        if c < prev + 100:
            continue
        out.append(raw[prev:c])
        kind, k = int(rng.integers(0, 3)), int(rng.integers(1, 12))
        k += k % 5 == 0
        if kind == 0:  # garbage
            out.append(rng.integers(0, 256, k).astype(np.uint8).tobytes())
            prev = c
        elif kind == 1:  # bytes lost on the line
            prev = c + min(k, 4)
        else:  # a stretch repeated
            out.append(raw[c - k:c])
            prev = c
    out.append(raw[prev:])
    return P.decode_nodes(raw), b"".join(out)


@pytest.mark.parametrize("seed", range(12))
def test_no_scan_built_from_a_slipped_stream_holds_a_node_that_was_not_sent(seed):
    truth, stream = _slipped_stream(seed)
    sent = set(zip(truth.start.tolist(), truth.quality.tolist(), truth.angle_q6.tolist(), truth.distance_q2.tolist()))
    rs = RevolutionStream()
    revs = [r for i in range(0, len(stream), 97) for r in rs.feed(stream[i:i + 97])]
    clean = [r for r in revs if r.clean]
    assert len(revs) >= 7 and rs.parser.dropped > 0  # a start node next to a slip may be dropped: two revolutions merge
    for r in clean:
        n = r.nodes
        assert set(zip(n.start.tolist(), n.quality.tolist(), n.angle_q6.tolist(), n.distance_q2.tolist())) <= sent
    # every byte in is a node out, dropped, or still buffered
    p = rs.parser
    assert p.nodes * 5 + p.dropped + len(p._buf) == len(stream)
