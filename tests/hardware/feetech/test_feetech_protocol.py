"""The Feetech STS/SCS packet layer: framing, checksum, sign-magnitude values, the resyncing parser."""
from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from emos.actors.hardware.feetech import protocol as P
from emos.actors.hardware.feetech.emulator import ServoModel
from emos.actors.hardware.feetech.protocol import Instruction, Reg

pytestmark = pytest.mark.unit


def test_ping_and_read_match_the_documents_examples():
    # Feetech's protocol manual: PING servo 1 is FF FF 01 02 01 FB; READ 2 bytes at 0x38 (present
    # position) of servo 1 is FF FF 01 04 02 38 02 BE.
    assert P.ping(1) == bytes.fromhex("ffff010201fb")
    assert P.read(1, Reg.PRESENT_POSITION.address, 2) == bytes.fromhex("ffff0104023802be")
    assert P.checksum([1, 2, 1]) == 0xFB


def test_sync_packets_layout():
    sr = P.sync_read(56, 2, [1, 2, 3])
    assert sr[:5] == bytes((0xFF, 0xFF, 0xFE, 7, Instruction.SYNC_READ)) and sr[5:10] == bytes((56, 2, 1, 2, 3))
    sw = P.sync_write(42, 2, {1: b"\x00\x08", 2: b"\xff\x0f"})
    assert sw[2:5] == bytes((0xFE, 10, Instruction.SYNC_WRITE))
    assert sw[5:13] == bytes((42, 2, 1, 0x00, 0x08, 2, 0xFF, 0x0F))
    assert sw[-1] == P.checksum(sw[2:-1])
    with pytest.raises(P.FeetechProtocolError, match="servo 2 got 1"):
        P.sync_write(42, 2, {2: b"\x00"})


@given(sid=st.integers(0, P.MAX_ID), code=st.integers(0, 0x7F), params=st.binary(max_size=40))
def test_status_round_trip(sid, code, params):
    parser = P.PacketParser(status=True)
    assert parser.feed(P.status(sid, code, params)) == [P.Packet(sid, code, params)]
    assert parser.dropped == 0


@given(value=st.integers(-32767, 32767))
def test_sign_magnitude_bit_15(value):
    raw = P.encode_sign_magnitude(value)
    assert P.decode_sign_magnitude(raw) == value
    assert (raw >> 15) == (1 if value < 0 else 0) and (raw & 0x7FFF) == abs(value)
    assert P.decode_value(Reg.GOAL_SPEED, P.encode_value(Reg.GOAL_SPEED, value)) == value


def test_negative_speed_is_sign_magnitude_not_twos_complement():
    assert P.encode_value(Reg.GOAL_SPEED, -100) == bytes((0x64, 0x80))  # little-endian 0x8064
    assert P.decode_value(Reg.PRESENT_SPEED, bytes((0x64, 0x80))) == -100
    assert P.encode_value(Reg.GOAL_POSITION, 2048) == b"\x00\x08"
    with pytest.raises(P.FeetechProtocolError):
        P.encode_value(Reg.GOAL_SPEED, 40000)


def test_sign_helpers_agree_with_the_reference_sdk():
    sdk = pytest.importorskip("scservo_sdk")
    for value in (-32767, -1000, -1, 0, 1, 4095, 32767):
        assert P.encode_sign_magnitude(value) == sdk.SCS_TOSCS(value, 15)
        assert P.decode_sign_magnitude(P.encode_sign_magnitude(value)) == sdk.SCS_TOHOST(P.encode_sign_magnitude(value), 15)


_garbage = st.binary(max_size=12).map(lambda b: bytes(x for x in b if x != 0xFF))  # no header can start inside


@settings(max_examples=150)
@given(packets=st.lists(st.tuples(st.integers(0, P.MAX_ID), st.integers(0, 0x7F), st.binary(max_size=16)), max_size=6),
       gaps=st.lists(_garbage, min_size=7, max_size=7), cut=st.integers(1, 7))
def test_resync_over_garbage_in_any_chunking(packets, gaps, cut):
    stream = bytearray()
    for (sid, code, params), gap in zip(packets, gaps, strict=False):
        stream += gap + P.status(sid, code, params)
    stream += gaps[-1]
    parser = P.PacketParser(status=True)
    got = []
    for i in range(0, len(stream), cut):
        got += parser.feed(bytes(stream[i: i + cut]))
    assert got == [P.Packet(*p) for p in packets]
    assert parser.dropped == sum(len(g) for g in gaps[: len(packets)]) + len(gaps[-1])


def test_corrupt_packet_is_never_returned_and_the_next_one_is():
    good1, good2 = P.status(1, 0, b"\x00\x08"), P.status(2, 0, b"\x10\x04")
    bad = bytearray(P.status(3, 0, b"\x34\x12"))
    bad[5] ^= 0x40  # a flipped bit in a parameter: the checksum no longer holds
    parser = P.PacketParser(status=True)
    got = parser.feed(good1 + bytes(bad) + b"\xff\xff\xff" + good2)
    assert got == [P.Packet(1, 0, b"\x00\x08"), P.Packet(2, 0, b"\x10\x04")]
    assert parser.dropped == len(bad) + 3


def test_impossible_header_fields_resync():
    parser = P.PacketParser(status=True)
    # ID 0xFE is broadcast (never a status), LEN 1 is too short, error byte 0x80 is invalid (SDK rxPacket)
    junk = b"\xff\xff\xfe\x02\x00\xff" + b"\xff\xff\x01\x01\x00" + bytes(P.status(1, 0x80))
    assert parser.feed(junk + P.status(4, 0, b"\x01")) == [P.Packet(4, 0, b"\x01")]
    assert parser.dropped == len(junk)
    # instruction packets may be broadcast
    assert P.PacketParser(status=False).feed(P.sync_read(56, 2, [1])) == [P.Packet(0xFE, 0x82, bytes((56, 2, 1)))]


def test_corrupt_length_resyncs_once_its_claimed_bytes_arrived():
    bad = bytearray(P.status(1, 0, b"\x00\x08"))
    bad[3] = 60  # LEN says 60: the parser waits for them, then finds the checksum wrong
    parser = P.PacketParser(status=True)
    good = P.status(2, 0, b"\x01\x02")
    assert parser.feed(bytes(bad) + good) == []
    assert parser.feed(bytes(70)) == [P.Packet(2, 0, b"\x01\x02")]
    # a host that knows the answer's length rejects the bad LEN at once
    parser = P.PacketParser(status=True)
    parser.expect_length(4)
    assert parser.feed(bytes(bad) + good) == [P.Packet(2, 0, b"\x01\x02")]
    assert parser.dropped == len(bad)


# -- the emulated servo's motion, on a clock the test moves --------------------------------------
class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_servo_moves_at_its_speed_limit():
    clock = Clock()
    servo = ServoModel(1, clock=clock)
    servo.write(Reg.TORQUE_ENABLE.address, b"\x01")
    servo.write(Reg.GOAL_POSITION.address, P.encode_value(Reg.GOAL_POSITION, 4000))
    clock.t = 0.25
    servo.update()
    # 0.222 s / 60 deg at 7.4 V = 3072 steps/s: 768 steps in 0.25 s
    assert servo.get(Reg.PRESENT_POSITION) == 2048 + 768
    assert servo.get(Reg.PRESENT_SPEED) == 3072 and servo.table[Reg.MOVING.address] == 1
    clock.t = 1.0
    servo.update()
    assert servo.get(Reg.PRESENT_POSITION) == 4000 and servo.table[Reg.MOVING.address] == 0


def test_servo_goal_speed_and_direction_and_torque_off():
    clock = Clock()
    servo = ServoModel(1, clock=clock)
    servo.write(Reg.GOAL_POSITION.address, P.encode_value(Reg.GOAL_POSITION, 1000))
    clock.t = 1.0
    servo.update()
    assert servo.get(Reg.PRESENT_POSITION) == 2048  # torque off: it does not move
    servo.write(Reg.TORQUE_ENABLE.address, b"\x01")
    servo.write(Reg.GOAL_SPEED.address, P.encode_value(Reg.GOAL_SPEED, 500))
    clock.t = 1.5
    servo.update()
    assert servo.get(Reg.PRESENT_POSITION) == 2048 - 250
    assert servo.get(Reg.PRESENT_SPEED) == -500  # sign-magnitude on the wire
    assert servo.table[Reg.PRESENT_SPEED.address + 1] & 0x80
    assert not servo.write(250, b"\x00" * 10)  # past the table: refused
    assert servo.read(Reg.MODEL_NUMBER.address, 2) == P.STS3215_MODEL.to_bytes(2, "little")
