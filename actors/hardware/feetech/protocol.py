"""The Feetech STS/SCS serial-bus servo protocol (STS3215: the servos of the SO-100/SO-101 arm).

Written from Feetech's public protocol description and its reference SDK (PyPI
``feetech-servo-sdk``, module ``scservo_sdk``: ``protocol_packet_handler.py``,
``group_sync_read.py``, ``scservo_def.py``), with the register names LeRobot's feetech motor bus
uses for the STS3215 (``lerobot/motors/feetech/tables.py``).

Framing (half-duplex TTL bus, 8N1, 1 Mbaud by default)::

    instruction:  0xFF 0xFF ID LEN INSTR PARAM... CHECKSUM
    status:       0xFF 0xFF ID LEN ERROR PARAM... CHECKSUM
    LEN      = number of PARAMs + 2 (the INSTR/ERROR byte and the checksum)
    CHECKSUM = ~(ID + LEN + INSTR/ERROR + sum(PARAMs)) & 0xFF

Instructions: PING 0x01, READ 0x02 (addr, n), WRITE 0x03 (addr, data...), SYNC_READ 0x82
(broadcast ID 0xFE; addr, n, id...: every listed servo answers with its own status packet, in the
order listed), SYNC_WRITE 0x83 (broadcast; addr, n, then per servo id + n bytes; no answer).
Multi-byte registers are little-endian (the SDK's ``SCS_END = 0`` for STS). Signed STS values
(goal and present speed: LeRobot's STS encodings table gives them sign bit 15) are sign-magnitude (the SDK's ``SCS_TOHOST(a, 15)`` /
``SCS_TOSCS``), not two's complement.
"""
from __future__ import annotations

import enum
from collections.abc import Iterable, Mapping
from typing import NamedTuple

from emos.errors import EmosError

HEADER = b"\xff\xff"
BROADCAST_ID = 0xFE
MAX_ID = 0xFD  # 0xFE is broadcast; a status packet never carries it (SDK rxPacket: ID > 0xFD is invalid)
MAX_LEN = 250  # the SDK's TXPACKET_MAX_LEN / RXPACKET_MAX_LEN bound the whole packet
STS3215_MODEL = 777  # model number register (address 3) of an STS3215, as LeRobot's MODEL_NUMBER_TABLE says
STEPS_PER_TURN = 4096  # the STS3215's magnetic encoder: 0..4095 per revolution
#: The STS3215's no-load speed: 0.222 s / 60 deg at 7.4 V (Feetech's STS3215 data sheet) =
#: 270 deg/s = 4.71 rad/s = 3072 steps/s.
MAX_SPEED_STEPS_PER_S = 3072


class Instruction(enum.IntEnum):
    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83


class ErrorBit(enum.IntFlag):
    """Status packet error byte (the SDK's ERRBIT_*)."""

    VOLTAGE = 1
    ANGLE = 2
    OVERHEAT = 4
    OVERELE = 8
    OVERLOAD = 32


class Register(NamedTuple):
    address: int
    size: int
    signed: bool = False  # sign-magnitude, sign in the top bit (15 for 2 bytes)


#: The STS3215 control table registers this package uses (Feetech STS memory table; LeRobot's
#: STS_SMS_SERIES_CONTROL_TABLE names). EEPROM area below 40, SRAM from 40.
class Reg:
    MODEL_NUMBER = Register(3, 2)
    ID = Register(5, 1)
    BAUD_RATE = Register(6, 1)
    RETURN_DELAY_TIME = Register(7, 1)  # units of 2 us; factory default 250 (= 500 us); LeRobot writes 0
    STATUS_RETURN_LEVEL = Register(8, 1)  # 0: answer only PING/READ; 1: answer everything
    MIN_POSITION_LIMIT = Register(9, 2)
    MAX_POSITION_LIMIT = Register(11, 2)
    TORQUE_ENABLE = Register(40, 1)
    ACCELERATION = Register(41, 1)
    GOAL_POSITION = Register(42, 2)
    GOAL_TIME = Register(44, 2)
    GOAL_SPEED = Register(46, 2, signed=True)  # steps/s, sign bit 15; 0 = the servo's maximum speed
    LOCK = Register(55, 1)
    PRESENT_POSITION = Register(56, 2)  # 0..4095 steps
    PRESENT_SPEED = Register(58, 2, signed=True)
    PRESENT_LOAD = Register(60, 2)  # sign in bit 10 on the STS; read as raw here
    PRESENT_VOLTAGE = Register(62, 1)  # units of 0.1 V
    PRESENT_TEMPERATURE = Register(63, 1)  # deg C
    MOVING = Register(66, 1)


TABLE_SIZE = 256  # addresses are one byte


class FeetechProtocolError(EmosError, ValueError):
    """Bytes or values that the protocol does not allow (names what and why)."""


# -- checksum, values ------------------------------------------------------------------------------
def checksum(body: Iterable[int]) -> int:
    """~(ID + LEN + INSTR/ERROR + params) & 0xFF: ``body`` is every byte after the 0xFF 0xFF header."""
    return ~sum(body) & 0xFF


def encode_sign_magnitude(value: int, sign_bit: int = 15) -> int:
    """A signed int as the STS sign-magnitude register value (the SDK's ``SCS_TOSCS``)."""
    magnitude = abs(int(value))
    if magnitude >= 1 << sign_bit:
        raise FeetechProtocolError(f"value {value} does not fit in a {sign_bit}-bit magnitude with sign bit {sign_bit}")
    return magnitude | (1 << sign_bit) if value < 0 else magnitude


def decode_sign_magnitude(raw: int, sign_bit: int = 15) -> int:
    """The STS sign-magnitude register value as a signed int (the SDK's ``SCS_TOHOST``)."""
    magnitude = raw & ((1 << sign_bit) - 1)
    return -magnitude if raw & (1 << sign_bit) else magnitude


def encode_value(reg: Register, value: int) -> bytes:
    """A register value as its little-endian bytes (sign-magnitude where the register is signed)."""
    raw = encode_sign_magnitude(value, 8 * reg.size - 1) if reg.signed else int(value)
    if not 0 <= raw < 1 << (8 * reg.size):
        raise FeetechProtocolError(f"value {value} does not fit register {reg.address} ({reg.size} byte(s))")
    return raw.to_bytes(reg.size, "little")


def decode_value(reg: Register, data: bytes) -> int:
    if len(data) != reg.size:
        raise FeetechProtocolError(f"register {reg.address} is {reg.size} byte(s), got {len(data)}")
    raw = int.from_bytes(data, "little")
    return decode_sign_magnitude(raw, 8 * reg.size - 1) if reg.signed else raw


# -- packets ---------------------------------------------------------------------------------------
class Packet(NamedTuple):
    """One packet: ``code`` is the instruction (instruction packets) or the error byte (status)."""

    id: int
    code: int
    params: bytes


def encode_packet(servo_id: int, code: int, params: bytes = b"") -> bytes:
    if not 0 <= servo_id <= BROADCAST_ID:
        raise FeetechProtocolError(f"servo id must be 0..{BROADCAST_ID}, got {servo_id}")
    if not 0 <= code <= 0xFF:
        raise FeetechProtocolError(f"instruction/error byte must be 0..255, got {code}")
    length = len(params) + 2
    if length + 4 > MAX_LEN:
        raise FeetechProtocolError(f"packet of {length + 4} bytes exceeds the protocol's {MAX_LEN}")
    body = bytes((servo_id, length, code)) + bytes(params)
    return HEADER + body + bytes((checksum(body),))


def ping(servo_id: int) -> bytes:
    return encode_packet(servo_id, Instruction.PING)


def read(servo_id: int, address: int, length: int) -> bytes:
    return encode_packet(servo_id, Instruction.READ, bytes((address, length)))


def write(servo_id: int, address: int, data: bytes) -> bytes:
    return encode_packet(servo_id, Instruction.WRITE, bytes((address,)) + bytes(data))


def sync_read(address: int, length: int, ids: Iterable[int]) -> bytes:
    return encode_packet(BROADCAST_ID, Instruction.SYNC_READ, bytes((address, length, *ids)))


def sync_write(address: int, length: int, data: Mapping[int, bytes]) -> bytes:
    params = bytearray((address, length))
    for servo_id, chunk in data.items():
        if len(chunk) != length:
            raise FeetechProtocolError(f"sync write of {length} byte(s) per servo: servo {servo_id} got {len(chunk)}")
        params.append(servo_id)
        params += chunk
    return encode_packet(BROADCAST_ID, Instruction.SYNC_WRITE, bytes(params))


def status(servo_id: int, error: int = 0, params: bytes = b"") -> bytes:
    return encode_packet(servo_id, error, params)


# -- the streaming parser --------------------------------------------------------------------------
class PacketParser:
    """Splits a byte stream into packets, resyncing on 0xFF 0xFF and the checksum.

    ``feed(data)`` returns the complete, checksum-valid packets found so far. A candidate whose
    header fields are impossible (ID 0xFF, LEN < 2 or too long, for status packets an error byte
    > 0x7F as the SDK checks) or whose checksum fails loses its first byte, and the search for a
    header starts again from the next byte: a corrupt packet is never returned, and a good packet
    right behind garbage is still found. ``dropped`` counts every byte discarded.

    A corrupt LEN byte that claims a long packet would hide the packets behind it until that many
    bytes arrived. The host knows how long the answers it asked for are: ``expect_length(n)``
    makes every other LEN impossible, so such noise costs one byte, not the transaction.
    """

    def __init__(self, *, status: bool) -> None:
        self.status = status  # status packets (from servos) vs instruction packets (from the host)
        self.length: int | None = None  # the only LEN accepted, when set
        self._buf = bytearray()
        self.dropped = 0
        self.packets = 0

    def reset(self) -> None:
        self.dropped += len(self._buf)
        self._buf.clear()

    def expect_length(self, length: int | None) -> None:
        """Accept only packets whose LEN byte is ``length`` (None: any possible LEN)."""
        self.length = length

    def feed(self, data: bytes) -> list[Packet]:
        buf = self._buf
        buf += data
        out: list[Packet] = []
        while True:
            start = buf.find(HEADER)
            if start < 0:
                # keep a trailing 0xFF: it may be the first half of the next header
                keep = 1 if buf[-1:] == b"\xff" else 0
                self.dropped += len(buf) - keep
                del buf[: len(buf) - keep]
                return out
            if start:
                self.dropped += start
                del buf[:start]
            if len(buf) < 4:
                return out
            servo_id, length = buf[2], buf[3]
            if (servo_id > (MAX_ID if self.status else BROADCAST_ID) or length < 2 or length + 4 > MAX_LEN
                    or (self.length is not None and length != self.length)):
                self._drop_one()
                continue
            total = length + 4
            if len(buf) < total:
                return out
            code = buf[4]
            if (self.status and code > 0x7F) or buf[total - 1] != checksum(buf[2: total - 1]):
                self._drop_one()
                continue
            out.append(Packet(servo_id, code, bytes(buf[5: total - 1])))
            self.packets += 1
            del buf[:total]

    def _drop_one(self) -> None:
        del self._buf[:1]
        self.dropped += 1
