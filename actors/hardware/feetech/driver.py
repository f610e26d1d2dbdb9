"""``FeetechBus``: the host side of a Feetech STS/SCS servo bus over a serial port (pyserial).

    bus = FeetechBus("/dev/ttyUSB0")          # 1 Mbaud, the STS3215's factory rate
    bus.open()                                 # FeetechPortError names a missing or taken port
    bus.ping(1)                                # model number, or FeetechNoAnswer naming the servo
    positions = bus.sync_read(Reg.PRESENT_POSITION, [1, 2, 3])   # {id: value} of the servos that answered
    bus.sync_write(Reg.GOAL_POSITION, {1: 2048, 2: 1000})

Blocking, one transaction at a time (the bus is half duplex). A dead port (the USB adapter was
pulled) raises :class:`FeetechDisconnected` naming the port; the caller closes and reopens.
Corrupt or stray bytes on the line never become values: the parser resyncs and counts them in
:attr:`FeetechBus.dropped_bytes`.
"""
from __future__ import annotations

import os
import select
import termios
import time
from collections.abc import Iterable, Mapping
from typing import Any

from emos.errors import EmosError, TransportError

from . import protocol as P
from .protocol import Register

DEFAULT_BAUDRATE = 1_000_000


class FeetechError(EmosError):
    """A Feetech bus failure; the message names the port and, where one is at fault, the servo."""


class FeetechPortError(FeetechError, TransportError):
    """The serial port does not exist, is taken, or cannot be set up."""


class FeetechDisconnected(FeetechError, TransportError):
    """The serial port went away mid-run (unplugged)."""


class FeetechNoAnswer(FeetechError):
    """Servos that did not answer in time; ``ids`` lists them."""

    def __init__(self, message: str, ids: Iterable[int]) -> None:
        super().__init__(message)
        self.ids = sorted(ids)


class FeetechBus:
    """A serial port with STS3215 servos on it (module docstring).

    ``timeout``: seconds to wait for the answers of one transaction beyond their wire time
    (the SDK waits 2 x 16 ms USB latency + 2 ms; a direct UART answers in well under 1 ms).
    """

    def __init__(self, port: str, baudrate: int = DEFAULT_BAUDRATE, timeout: float = 0.02) -> None:
        if not isinstance(port, str) or not port:
            raise ValueError(f"FeetechBus: port must be a device path such as '/dev/ttyUSB0', got {port!r}")
        self.port = port
        self.baudrate = int(baudrate)
        self.timeout = float(timeout)
        self.byte_time = 10.0 / self.baudrate
        self._serial: Any = None
        self._parser = P.PacketParser(status=True)
        self.error_bits: dict[int, int] = {}  # last non-zero error byte per servo

    # -- the port --------------------------------------------------------------------------------
    @property
    def is_open(self) -> bool:
        return self._serial is not None

    @property
    def dropped_bytes(self) -> int:
        return self._parser.dropped

    def open(self) -> None:
        import serial  # pyserial: the `hardware` extra

        try:
            # exclusive: a second program on the same bus would interleave packets
            self._serial = serial.Serial(self.port, self.baudrate, timeout=0, write_timeout=1.0, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            self._serial = None
            raise FeetechPortError(f"Feetech bus: cannot open serial port {self.port!r} at {self.baudrate} baud "
                                   f"(missing, taken by another program, or not a serial device): {exc}") from exc
        self._parser.reset()

    def close(self) -> None:
        ser, self._serial = self._serial, None
        if ser is not None:
            try:
                ser.close()
            except Exception:  # a dead port may fail to close; it is gone either way
                pass

    def __enter__(self) -> FeetechBus:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- transactions ----------------------------------------------------------------------------
    def transact(self, packet: bytes, expect: Iterable[int], answer_len: int) -> dict[int, P.Packet]:
        """Send ``packet`` and collect the status packets of the servos in ``expect`` (each
        ``answer_len`` bytes on the wire). Returns those that answered in time, by id."""
        import serial

        ser = self._serial
        if ser is None:
            raise FeetechDisconnected(f"Feetech bus: serial port {self.port!r} is not open")
        expected = list(expect)
        got: dict[int, P.Packet] = {}
        try:
            fd = ser.fileno()
            ser.reset_input_buffer()  # a late answer of a previous transaction is not ours
            self._parser.reset()
            self._parser.expect_length(answer_len - 4 if expected else None)
            ser.write(packet)
            if not expected:
                return got
            wire = (len(packet) + answer_len * len(expected)) * self.byte_time
            deadline = time.monotonic() + wire + self.timeout
            while len(got) < len(expected):
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                # select + os.read: pyserial's read() reconfigures termios on every timeout change
                ready, _, _ = select.select([fd], [], [], left)
                if not ready:
                    break
                data = os.read(fd, 4096)
                if not data:
                    raise OSError(f"serial port {self.port!r} reports end of file")
                for pkt in self._parser.feed(data):
                    if pkt.id in expected:
                        got[pkt.id] = pkt
                        if pkt.code:
                            self.error_bits[pkt.id] = pkt.code
        except (serial.SerialException, OSError, termios.error) as exc:
            raise FeetechDisconnected(f"Feetech bus: serial port {self.port!r} failed (unplugged?): {exc}") from exc
        return got

    def _one(self, packet: bytes, servo_id: int, answer_len: int, what: str) -> P.Packet:
        got = self.transact(packet, [servo_id], answer_len)
        if servo_id not in got:
            raise FeetechNoAnswer(f"Feetech bus {self.port!r}: servo {servo_id} did not answer {what}", [servo_id])
        return got[servo_id]

    def ping(self, servo_id: int) -> int:
        """Pings a servo and returns its model number (777 for an STS3215), as the SDK's ``ping`` does."""
        self._one(P.ping(servo_id), servo_id, 6, "PING")
        return self.read(servo_id, P.Reg.MODEL_NUMBER)

    def read_bytes(self, servo_id: int, address: int, length: int) -> bytes:
        pkt = self._one(P.read(servo_id, address, length), servo_id, 6 + length, f"READ of {length} byte(s) at {address}")
        if len(pkt.params) != length:
            raise FeetechError(f"Feetech bus {self.port!r}: servo {servo_id} answered {len(pkt.params)} byte(s) "
                               f"to a READ of {length} at {address}")
        return pkt.params

    def read(self, servo_id: int, reg: Register) -> int:
        return P.decode_value(reg, self.read_bytes(servo_id, reg.address, reg.size))

    def write(self, servo_id: int, reg: Register, value: int) -> None:
        self._one(P.write(servo_id, reg.address, P.encode_value(reg, value)), servo_id, 6, f"WRITE at {reg.address}")

    def sync_read(self, reg: Register, ids: Iterable[int]) -> dict[int, int]:
        """One SYNC_READ of ``reg`` from every servo in ``ids``: {id: value} of those that answered."""
        ids = list(ids)
        got = self.transact(P.sync_read(reg.address, reg.size, ids), ids, 6 + reg.size)
        return {i: P.decode_value(reg, pkt.params) for i, pkt in got.items() if len(pkt.params) == reg.size}

    def sync_write(self, reg: Register, values: Mapping[int, int]) -> None:
        """One SYNC_WRITE of ``reg`` to every servo in ``values`` (no answer: it is a broadcast)."""
        self.transact(P.sync_write(reg.address, reg.size, {i: P.encode_value(reg, v) for i, v in values.items()}), [], 0)
