"""The iRobot Create 2 Open Interface (OI): opcodes, sensor packets, the stream frame, a parser.

Written from the "iRobot Create 2 Open Interface (OI) Specification based on the iRobot Roomba
600" (iRobot, 2015-2018; cited below as "OI spec" with its section names):

* Serial Port Settings: 115200 baud, 8N1, no flow control (the default baud).
* Getting Started / Mode Commands: Start 128 (-> Passive; must come first), Safe 131,
  Full 132, Stop 173 (the OI stops responding; Create 2 only).
* Actuator Commands, "Drive Direct" 145: ``[145][Right velocity high][low][Left velocity high]
  [low]``, each a signed 16-bit mm/s value, high byte first, range -500..500.
* Input Commands, "Sensors" 142 ``[142][packet id]`` (one reply, no header); "Stream" 148
  ``[148][n][id 1]..[id n]``: every 15 ms the robot sends ``[19][n-bytes][id 1][data 1]...
  [id n][data n][checksum]``, where n-bytes counts the bytes between itself and the checksum,
  and the checksum makes the low byte of the sum of every byte from the header to the checksum
  0; "Pause/Resume Stream" 150 ``[150][0|1]``.
* Sensor Packets: 7 bumps and wheel drops (bit 0 bump right, 1 bump left, 2 wheel drop right,
  3 wheel drop left); 9-12 cliff left, front left, front right, right (0/1); 21 charging state;
  22 voltage (mV, unsigned 16); 23 current (mA, signed 16); 24 temperature (degC, signed 8);
  25 battery charge and 26 capacity (mAh, unsigned 16); 35 OI mode (0 off, 1 passive, 2 safe,
  3 full); 43/44 left/right encoder counts: "signed 16-bit, high byte first; rolls over to
  -32768 after it reaches 32767" (so only differences modulo 2**16 are meaningful: see
  :func:`encoder_delta`); group packet 100 = packets 7-58 (80 bytes).
* Roomba physical dimensions / packet 43 note: 508.8 encoder counts per wheel revolution,
  72.0 mm wheel diameter, 235 mm between the wheels.

Everything here is pure (bytes in, values out): the driver, the emulator and the tests share it.
"""
from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Iterator

import attrs

from emos.errors import EmosError

# -- opcodes (OI spec, "Open Interface Command Reference") ---------------------------------------
START = 128
RESET = 7
BAUD = 129
SAFE = 131
FULL = 132
POWER = 133
DRIVE = 137
LEDS = 139
SONG = 140
PLAY = 141
SENSORS = 142
DRIVE_DIRECT = 145
DRIVE_PWM = 146
STREAM = 148
QUERY_LIST = 149
PAUSE_RESUME_STREAM = 150
DIGIT_LEDS_ASCII = 164
STOP = 173

STREAM_HEADER = 19
BAUD_RATE = 115200
STREAM_PERIOD_S = 0.015  # OI spec, Stream: "sent every 15 ms"
MAX_WHEEL_SPEED_MM_S = 500

# -- robot geometry (OI spec, "Roomba Physical Dimensions" and the encoder packet notes) ---------
COUNTS_PER_REV = 508.8
WHEEL_DIAMETER_M = 0.072
WHEEL_BASE_M = 0.235
M_PER_COUNT = math.pi * WHEEL_DIAMETER_M / COUNTS_PER_REV  # 0.4446 mm

# -- OI modes (packet 35) ------------------------------------------------------------------------
MODE_OFF, MODE_PASSIVE, MODE_SAFE, MODE_FULL = 0, 1, 2, 3

# -- sensor packets: id -> (data bytes, struct format) -------------------------------------------
PKT_BUMPS_WHEELDROPS = 7
PKT_CLIFF_LEFT, PKT_CLIFF_FRONT_LEFT, PKT_CLIFF_FRONT_RIGHT, PKT_CLIFF_RIGHT = 9, 10, 11, 12
PKT_CHARGING_STATE = 21
PKT_VOLTAGE, PKT_CURRENT, PKT_TEMPERATURE, PKT_CHARGE, PKT_CAPACITY = 22, 23, 24, 25, 26
PKT_OI_MODE = 35
PKT_ENCODER_LEFT, PKT_ENCODER_RIGHT = 43, 44
PKT_GROUP_ALL = 100  # packets 7..58

# Sizes and signedness of packets 7..58 (OI spec, "Roomba Open Interface Sensors Quick Reference").
_SIZES_7_58: dict[int, str] = {
    7: "B", 8: "B", 9: "B", 10: "B", 11: "B", 12: "B", 13: "B", 14: "B", 15: "b", 16: "B", 17: "B", 18: "B",
    19: "h", 20: "h", 21: "B", 22: "H", 23: "h", 24: "b", 25: "H", 26: "H", 27: "H", 28: "H", 29: "H", 30: "H",
    31: "H", 32: "B", 33: "H", 34: "B", 35: "B", 36: "B", 37: "B", 38: "B", 39: "h", 40: "h", 41: "h", 42: "h",
    43: "h", 44: "h", 45: "B", 46: "H", 47: "H", 48: "H", 49: "H", 50: "H", 51: "H", 52: "B", 53: "B", 54: "h",
    55: "h", 56: "h", 57: "h", 58: "B",
}
PACKET_FORMATS: dict[int, str] = dict(_SIZES_7_58)
PACKET_SIZES: dict[int, int] = {pid: struct.calcsize(">" + f) for pid, f in PACKET_FORMATS.items()}
PACKET_SIZES[PKT_GROUP_ALL] = sum(PACKET_SIZES[p] for p in range(7, 59))  # 80

# What our driver streams: everything it publishes, nothing more (23 data bytes every 15 ms).
DRIVER_STREAM_IDS: tuple[int, ...] = (
    PKT_BUMPS_WHEELDROPS, PKT_CLIFF_LEFT, PKT_CLIFF_FRONT_LEFT, PKT_CLIFF_FRONT_RIGHT, PKT_CLIFF_RIGHT,
    PKT_CHARGING_STATE, PKT_VOLTAGE, PKT_CURRENT, PKT_CHARGE, PKT_CAPACITY, PKT_OI_MODE,
    PKT_ENCODER_LEFT, PKT_ENCODER_RIGHT,
)

BUMP_RIGHT, BUMP_LEFT, WHEELDROP_RIGHT, WHEELDROP_LEFT = 0x01, 0x02, 0x04, 0x08


class Create2ProtocolError(EmosError, ValueError):
    """Bytes or values that the OI spec does not allow (names the field and what was expected)."""


# -- encoding ------------------------------------------------------------------------------------
def clamp_speed(mm_s: float) -> int:
    """A wheel speed in mm/s, rounded and clamped to the OI's -500..500 (Drive Direct clause)."""
    if not math.isfinite(mm_s):
        raise Create2ProtocolError(f"Drive Direct: wheel speed must be a finite number of mm/s, got {mm_s!r}")
    return max(-MAX_WHEEL_SPEED_MM_S, min(MAX_WHEEL_SPEED_MM_S, int(round(mm_s))))


def drive_direct(right_mm_s: float, left_mm_s: float) -> bytes:
    """``[145][right hi][right lo][left hi][left lo]``: right wheel first (OI spec, Drive Direct)."""
    return struct.pack(">Bhh", DRIVE_DIRECT, clamp_speed(right_mm_s), clamp_speed(left_mm_s))


def stream_request(packet_ids: Iterable[int]) -> bytes:
    """``[148][n][ids...]`` (OI spec, Stream)."""
    ids = list(packet_ids)
    for pid in ids:
        if pid not in PACKET_SIZES or pid == PKT_GROUP_ALL:
            raise Create2ProtocolError(f"Stream: packet id {pid} is not a single sensor packet this module knows (7..58)")
    return bytes([STREAM, len(ids), *ids])


def pause_resume(resume: bool) -> bytes:
    """``[150][1]`` resumes, ``[150][0]`` pauses the stream (OI spec, Pause/Resume Stream)."""
    return bytes([PAUSE_RESUME_STREAM, 1 if resume else 0])


def checksum(body: bytes) -> int:
    """The byte that makes the 8-bit sum of ``body`` + it zero (OI spec, Stream)."""
    return (-sum(body)) & 0xFF


def encode_values(values: dict[int, int]) -> dict[int, bytes]:
    """Packet id -> its data bytes, big-endian, with the packet's signedness."""
    out: dict[int, bytes] = {}
    for pid, value in values.items():
        fmt = PACKET_FORMATS.get(pid)
        if fmt is None:
            raise Create2ProtocolError(f"sensor packet {pid}: unknown id (this module knows 7..58)")
        out[pid] = struct.pack(">" + fmt, value)
    return out


def encode_frame(values: dict[int, int], order: Iterable[int] | None = None) -> bytes:
    """One stream frame ``[19][n][id][data]...[checksum]`` holding ``values`` (id -> int)."""
    data = encode_values(values)
    body = b"".join(bytes([pid]) + data[pid] for pid in (order if order is not None else values))
    if len(body) > 255:
        raise Create2ProtocolError(f"stream frame: {len(body)} bytes of packets, at most 255 fit the n-bytes field")
    head = bytes([STREAM_HEADER, len(body)]) + body
    return head + bytes([checksum(head)])


def encode_group_100(values: dict[int, int]) -> bytes:
    """The 80-byte reply to ``[142][100]``: packets 7..58 in order, missing ones 0."""
    return b"".join(struct.pack(">" + PACKET_FORMATS[p], values.get(p, 0)) for p in range(7, 59))


def decode_group_100(data: bytes) -> dict[int, int]:
    """The 80-byte reply to ``[142][100]`` -> packet id -> value (packets 7..58)."""
    if len(data) != PACKET_SIZES[PKT_GROUP_ALL]:
        raise Create2ProtocolError(f"sensor group 100: expected {PACKET_SIZES[PKT_GROUP_ALL]} bytes, got {len(data)}")
    out, i = {}, 0
    for pid in range(7, 59):
        size = PACKET_SIZES[pid]
        out[pid] = decode_packet(pid, data[i: i + size])
        i += size
    return out


def decode_packet(pid: int, data: bytes) -> int:
    return int(struct.unpack(">" + PACKET_FORMATS[pid], data)[0])


def encoder_delta(new: int, old: int) -> int:
    """Counts travelled between two readings of a 16-bit counter that wraps (either signedness):
    the difference modulo 2**16 mapped to -32768..32767, so a roll-over is a small step."""
    d = (new - old) & 0xFFFF
    return d - 0x10000 if d >= 0x8000 else d


# -- the stream parser ---------------------------------------------------------------------------
@attrs.frozen
class SensorFrame:
    """One checked stream frame: packet id -> value (ints, decoded with the packet's sign)."""

    values: dict[int, int]

    def get(self, pid: int, default: int = 0) -> int:
        return self.values.get(pid, default)

    @property
    def bump_left(self) -> bool:
        return bool(self.get(PKT_BUMPS_WHEELDROPS) & BUMP_LEFT)

    @property
    def bump_right(self) -> bool:
        return bool(self.get(PKT_BUMPS_WHEELDROPS) & BUMP_RIGHT)

    @property
    def bumped(self) -> bool:
        return bool(self.get(PKT_BUMPS_WHEELDROPS) & (BUMP_LEFT | BUMP_RIGHT))

    @property
    def wheel_dropped(self) -> bool:
        return bool(self.get(PKT_BUMPS_WHEELDROPS) & (WHEELDROP_LEFT | WHEELDROP_RIGHT))

    @property
    def cliffs(self) -> tuple[bool, bool, bool, bool]:
        return (bool(self.get(PKT_CLIFF_LEFT)), bool(self.get(PKT_CLIFF_FRONT_LEFT)),
                bool(self.get(PKT_CLIFF_FRONT_RIGHT)), bool(self.get(PKT_CLIFF_RIGHT)))


class StreamParser:
    """Turns a byte stream into checked :class:`SensorFrame` s.

    Sync rules (OI spec, Stream): a frame starts at a 19; its n-bytes byte says how long it is;
    its body must be a sequence of known packet ids each followed by exactly its data size; the
    8-bit sum of header..checksum must be 0. A candidate that fails any rule costs one byte (the
    19 it started at) and the search restarts at the next byte, so a frame that begins inside a
    bad one is still found. Nothing that fails a rule is ever returned. ``dropped_bytes`` counts
    every byte thrown away; ``bad_checksums`` and ``bad_layouts`` the candidates rejected.
    ``expected_ids``, when given, also rejects frames that do not hold exactly those packets
    (and, before reading on, a header whose n-bytes is not theirs).
    """

    def __init__(self, expected_ids: Iterable[int] | None = None, max_buffer: int = 4096) -> None:
        self.expected_ids = tuple(expected_ids) if expected_ids is not None else None
        # With the packet list known, so is n-bytes: a header followed by any other n is noise,
        # rejected at once instead of waiting up to 255 bytes for its "end".
        self._expected_n = sum(1 + PACKET_SIZES[p] for p in self.expected_ids) if self.expected_ids is not None else None
        self._buf = bytearray()
        self._max_buffer = max_buffer
        self.frames = 0
        self.dropped_bytes = 0
        self.bad_checksums = 0
        self.bad_layouts = 0

    def feed(self, data: bytes) -> list[SensorFrame]:
        self._buf += data
        return list(self._drain())

    def _drop(self, n: int) -> None:
        del self._buf[:n]
        self.dropped_bytes += n

    def _drain(self) -> Iterator[SensorFrame]:
        buf = self._buf
        while buf:
            start = buf.find(STREAM_HEADER)
            if start < 0:
                self._drop(len(buf))
                return
            if start:
                self._drop(start)
            if len(buf) < 2:
                return
            n = buf[1]
            if self._expected_n is not None and n != self._expected_n:
                self.bad_layouts += 1
                self._drop(1)
                continue
            if len(buf) < n + 3:
                if len(buf) > self._max_buffer:  # cannot happen with n <= 255; bounds memory anyway
                    self._drop(1)
                    continue
                return  # wait for the rest
            frame = bytes(buf[: n + 3])
            if sum(frame) & 0xFF:
                self.bad_checksums += 1
                self._drop(1)
                continue
            values = self._layout(frame[2: n + 2])
            if values is None:
                self.bad_layouts += 1
                self._drop(1)
                continue
            del buf[: n + 3]
            self.frames += 1
            yield SensorFrame(values)

    def _layout(self, body: bytes) -> dict[int, int] | None:
        values: dict[int, int] = {}
        i = 0
        while i < len(body):
            pid = body[i]
            size = PACKET_SIZES.get(pid)
            if size is None or pid == PKT_GROUP_ALL or pid in values or i + 1 + size > len(body):
                return None
            values[pid] = decode_packet(pid, body[i + 1: i + 1 + size])
            i += 1 + size
        if self.expected_ids is not None and set(values) != set(self.expected_ids):
            return None
        return values
