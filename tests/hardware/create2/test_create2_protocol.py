"""Create 2 OI protocol units: encoding, the stream frame, the checksum, the resyncing parser."""
from __future__ import annotations

import random

import pytest

from emos.actors.hardware.create2 import protocol as P
from emos.actors.hardware.create2.odometry import DiffDriveOdometry

pytestmark = pytest.mark.unit

IDS = P.DRIVER_STREAM_IDS


def _values(seed: int) -> dict[int, int]:
    rng = random.Random(seed)
    v = {pid: rng.randint(0, 1) for pid in IDS}
    v.update({P.PKT_BUMPS_WHEELDROPS: rng.randint(0, 15), P.PKT_VOLTAGE: rng.randint(12000, 17000),
              P.PKT_CURRENT: rng.randint(-2000, 100), P.PKT_CHARGE: rng.randint(0, 2696), P.PKT_CAPACITY: 2696,
              P.PKT_OI_MODE: rng.randint(0, 3), P.PKT_CHARGING_STATE: 0,
              P.PKT_ENCODER_LEFT: rng.randint(-32768, 32767), P.PKT_ENCODER_RIGHT: rng.randint(-32768, 32767)})
    return v


def test_drive_direct_bytes_right_first_big_endian_clamped():
    # OI spec, Drive Direct: [145][right hi][right lo][left hi][left lo], -500..500 mm/s
    assert P.drive_direct(-200, 500) == bytes([145, 0xFF, 0x38, 0x01, 0xF4])
    assert P.drive_direct(900, -900) == bytes([145, 0x01, 0xF4, 0xFE, 0x0C])
    with pytest.raises(P.Create2ProtocolError, match="finite"):
        P.drive_direct(float("nan"), 0)


def test_stream_request_and_spec_example_checksum():
    assert P.stream_request([29, 13]) == bytes([148, 2, 29, 13])
    assert P.pause_resume(False) == bytes([150, 0]) and P.pause_resume(True) == bytes([150, 1])
    # The OI spec's own Stream example: 19 5 29 2 25 13 0 163; 8-bit sum of the frame is 0.
    frame = bytes([19, 5, 29, 2, 25, 13, 0])
    assert P.checksum(frame) == 163  # the Create 2 spec: (19+5+29+2+25+13+0+163) & 0xFF == 0
    parsed = P.StreamParser().feed(frame + bytes([163]))
    assert len(parsed) == 1 and parsed[0].values == {29: 0x0219, 13: 0}


@pytest.mark.parametrize("seed", range(20))
def test_frame_round_trip(seed):
    values = _values(seed)
    frame = P.encode_frame(values, IDS)
    assert frame[0] == 19 and frame[1] == len(frame) - 3 and sum(frame) & 0xFF == 0
    out = P.StreamParser(expected_ids=IDS).feed(frame)
    assert [f.values for f in out] == [values]


def test_one_byte_at_a_time_and_group_100_size():
    values = _values(1)
    parser = P.StreamParser(expected_ids=IDS)
    got = []
    for b in P.encode_frame(values, IDS) * 3:
        got += parser.feed(bytes([b]))
    assert [f.values for f in got] == [values] * 3 and parser.dropped_bytes == 0
    assert P.PACKET_SIZES[100] == 80 and len(P.encode_group_100(values)) == 80


def test_resync_on_garbage_truncated_and_corrupt_frames_with_counts():
    frames = [P.encode_frame(_values(i), IDS) for i in range(6)]
    garbage = bytes([19, 19, 7, 0, 19, 200, 1, 2, 3])  # headers that lead nowhere
    truncated = frames[1][:10]  # a frame cut short by a reset: the next one starts inside it
    corrupt = bytearray(frames[3])
    corrupt[5] ^= 0x40  # one flipped bit: the checksum catches it
    stream = garbage + frames[0] + truncated + frames[2] + bytes(corrupt) + frames[4] + b"\x00\xff" + frames[5]
    parser = P.StreamParser(expected_ids=IDS)
    got = []
    rng = random.Random(7)
    i = 0
    while i < len(stream):  # arbitrary read sizes, as a serial port delivers them
        n = rng.randint(1, 40)
        got += parser.feed(stream[i:i + n])
        i += n
    assert [f.values for f in got] == [_values(k) for k in (0, 2, 4, 5)]  # never a wrong frame
    assert parser.frames == 4
    assert parser.dropped_bytes == len(garbage) + len(truncated) + len(corrupt) + 2
    assert parser.bad_checksums + parser.bad_layouts >= 2


def test_random_noise_never_yields_a_frame_of_the_wrong_layout():
    rng = random.Random(3)
    noise = bytes(rng.randrange(256) for _ in range(20000))
    parser = P.StreamParser(expected_ids=IDS)
    out = parser.feed(noise)
    assert all(set(f.values) == set(IDS) for f in out)
    assert parser.dropped_bytes + sum(len(P.encode_frame(f.values, IDS)) for f in out) + len(parser._buf) == len(noise)


def test_encoder_wrap_around_is_a_small_step():
    # OI spec, packets 43/44: signed 16-bit, rolls over to -32768 after 32767
    assert P.encoder_delta(-32768, 32767) == 1
    assert P.encoder_delta(32767, -32768) == -1
    assert P.encoder_delta(5, 65530) == 11  # an unsigned reader's view gives the same step
    odo = DiffDriveOdometry()
    odo.update(32760, 32760, 0.015)
    odo.update(-32766, -32766, 0.015)  # +10 counts on both wheels across the roll-over
    assert odo.x == pytest.approx(10 * P.M_PER_COUNT) and odo.th == 0.0
