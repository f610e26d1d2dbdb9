"""The Slamtec RPLIDAR A1/A2 serial protocol: requests, response descriptors, the standard scan's
5-byte measurement nodes, and a streaming node parser that resynchronises on the protocol's own
check bits.

Written from Slamtec's public "RPLIDAR Interface Protocol and Application Notes" (A1 & A2; the
clauses below cite its sections and figures; later revisions renumber the figures, the text is
the same):

* §2 "Request Packets' Format" (Fig. 2-4): a request is ``0xA5, cmd`` and, when it carries a
  payload, ``size, payload..., checksum`` where checksum = 0 XOR 0xA5 XOR cmd XOR size XOR every
  payload byte. Little-endian byte order throughout.
* §2 "Response Packets' Format" (Fig. 2-5..2-8): a response descriptor is ``0xA5 0x5A``, a
  32-bit little-endian word holding the 30-bit data response length and (top 2 bits) the send
  mode (0 single response, 1 multiple responses), then one data type byte.
* §4 STOP (0x25) and RESET (0x40): no response; wait >= 1 ms (STOP) and >= 2 ms (RESET) before
  the next request.
* §4 SCAN (0x20), Fig. 4-4/4-5: descriptor ``A5 5A 05 00 00 40 81`` (5 bytes, multiple, 0x81),
  then one 5-byte node per sample: byte 0 = S (bit 0, start of a new 360 deg scan), S-bar
  (bit 1, always the inverse of S, "can be used as a data check bit"), quality (bits 2-7);
  byte 1 bit 0 = C ("check bit, constantly set to 1"), bits 1-7 = angle_q6[6:0]; byte 2 =
  angle_q6[14:7]; bytes 3-4 = distance_q2 (little-endian). Heading = angle_q6 / 64 degrees in
  [0, 360); distance = distance_q2 / 4 mm, 0 when the measurement is invalid. Samples are sent
  "only after the motor rotation becomes stable".
* Fig. 4-6: the angle grows clockwise seen from above, 0 deg = the device's heading.
* §4 GET_INFO (0x50), Fig. 4-16/4-17: descriptor ``A5 5A 14 00 00 00 04``; model, firmware
  minor, firmware major, hardware, 16-byte serial number.
* §4 GET_HEALTH (0x52), Fig. 4-19/4-20: descriptor ``A5 5A 03 00 00 00 06``; status (0 Good,
  1 Warning, 2 Error = Protection Stop), error_code[7:0], error_code[15:8] (little-endian).
* SET_MOTOR_PWM (0xF0, A2 and A1 with the accessory board): payload u16 PWM 0..1023 (660 is the
  SDK's default), sent with the payload checksum above. A bare A1 on the USB adapter turns its
  motor with the adapter's DTR line instead (DTR low = spin).

Resynchronisation (:class:`NodeParser`): the node has no length or CRC, only three check bits
(S xor S-bar must be 1, C must be 1) and the angle's range (angle_q6 < 360 * 64); samples also
come in rotation order, so consecutive nodes must be a small clockwise step apart (30 deg at
most; an A1 steps ~1 deg). A node that fails makes the parser drop ONE byte and look for sync
again; it re-locks only where ``confirm`` consecutive 5-byte candidates all pass. In sync, a
node is delivered only once the ``LOOKAHEAD`` (2) nodes after it passed as well: the check bits
live in bytes 0-2, so a node whose distance bytes slipped passes them itself and only the
alignment of its successors shows the slip (the nodes before a failure are dropped as suspect);
likewise the first node of a new lock is dropped (a stray byte glued to a real node's bytes 1-4
passes every check). Every dropped byte is counted.

Limits, stated plainly: a slip of a net multiple of 5 bytes inside one node's distance bytes
(or two nearby slips adding up to one) realigns the stream and breaks no rule of the protocol;
nothing can detect it, here or in Slamtec's SDK. Other slips are detected, but possibly a few
nodes late: the driver (``scan.RevolutionStream``) therefore never delivers a revolution in
which, or next to which, a byte was dropped (tests/hardware/rplidar: 12 seeds of random garbage,
lost and repeated bytes, no delivered scan holds a node that was not sent).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from emos.errors import EmosError

__all__ = [
    "SYNC", "SYNC2", "CMD_STOP", "CMD_RESET", "CMD_SCAN", "CMD_FORCE_SCAN", "CMD_GET_INFO", "CMD_GET_HEALTH",
    "CMD_SET_MOTOR_PWM", "ANS_TYPE_DEVINFO", "ANS_TYPE_DEVHEALTH", "ANS_TYPE_MEASUREMENT", "MODE_SINGLE", "MODE_MULTIPLE",
    "DEFAULT_MOTOR_PWM", "MAX_MOTOR_PWM", "NODE_SIZE", "DESCRIPTOR_SIZE", "ANGLE_Q6_FULL", "HEALTH_GOOD", "HEALTH_WARNING",
    "HEALTH_ERROR", "RplidarProtocolError", "Descriptor", "DeviceInfo", "Health", "Nodes", "request", "checksum", "motor_pwm_request",
    "find_descriptor", "encode_nodes", "decode_nodes", "node_valid_mask", "NodeParser",
    "SCAN_DESCRIPTOR", "INFO_DESCRIPTOR", "HEALTH_DESCRIPTOR",
]

SYNC = 0xA5  # request start flag; also response descriptor sync byte 1 (§2)
SYNC2 = 0x5A  # response descriptor sync byte 2

CMD_STOP = 0x25
CMD_RESET = 0x40
CMD_SCAN = 0x20
CMD_FORCE_SCAN = 0x21
CMD_GET_INFO = 0x50
CMD_GET_HEALTH = 0x52
CMD_SET_MOTOR_PWM = 0xF0

ANS_TYPE_DEVINFO = 0x04
ANS_TYPE_DEVHEALTH = 0x06
ANS_TYPE_MEASUREMENT = 0x81

MODE_SINGLE = 0
MODE_MULTIPLE = 1

DEFAULT_MOTOR_PWM = 660
MAX_MOTOR_PWM = 1023

NODE_SIZE = 5
DESCRIPTOR_SIZE = 7
ANGLE_Q6_FULL = 360 * 64  # angle_q6 is in [0, 360) degrees (Fig. 4-5)
INFO_SIZE = 20
HEALTH_SIZE = 3

HEALTH_GOOD, HEALTH_WARNING, HEALTH_ERROR = 0, 1, 2
HEALTH_NAMES = {HEALTH_GOOD: "Good", HEALTH_WARNING: "Warning", HEALTH_ERROR: "Error (Protection Stop)"}


class RplidarProtocolError(EmosError, ValueError):
    """Bytes that are not what the RPLIDAR protocol document says they must be."""


# -- requests (§2 Request Packets' Format) ------------------------------------------------------
def checksum(data: bytes) -> int:
    """XOR of every byte (the request checksum covers 0xA5, cmd, size and the payload)."""
    return int(np.bitwise_xor.reduce(np.frombuffer(data, dtype=np.uint8))) if data else 0


def request(cmd: int, payload: bytes | None = None) -> bytes:
    """One request packet: ``A5 cmd`` or ``A5 cmd size payload checksum``."""
    if not 0 <= cmd <= 0xFF:
        raise RplidarProtocolError(f"RPLIDAR request: command must be a byte, got {cmd!r}")
    head = bytes((SYNC, cmd))
    if payload is None:
        return head
    if len(payload) > 255:
        raise RplidarProtocolError(f"RPLIDAR request 0x{cmd:02X}: payload is {len(payload)} bytes, the size field holds at most 255")
    body = head + bytes((len(payload),)) + bytes(payload)
    return body + bytes((checksum(body),))


def motor_pwm_request(pwm: int) -> bytes:
    """SET_MOTOR_PWM (0xF0) with a u16 little-endian PWM in 0..1023 (0 stops the motor)."""
    if not isinstance(pwm, int) or not 0 <= pwm <= MAX_MOTOR_PWM:
        raise RplidarProtocolError(f"RPLIDAR motor PWM must be an int in 0..{MAX_MOTOR_PWM}, got {pwm!r}")
    return request(CMD_SET_MOTOR_PWM, struct.pack("<H", pwm))


# -- response descriptors (§2 Response Packets' Format) ------------------------------------------
@dataclass(frozen=True)
class Descriptor:
    """``A5 5A`` + u32 LE (length:30, send mode:2) + data type."""

    length: int
    mode: int
    dtype: int

    def encode(self) -> bytes:
        if not 0 <= self.length < (1 << 30) or not 0 <= self.mode <= 3 or not 0 <= self.dtype <= 0xFF:
            raise RplidarProtocolError(f"RPLIDAR descriptor out of range: {self}")
        return bytes((SYNC, SYNC2)) + struct.pack("<IB", self.length | (self.mode << 30), self.dtype)

    @classmethod
    def decode(cls, data: bytes) -> Descriptor:
        if len(data) != DESCRIPTOR_SIZE:
            raise RplidarProtocolError(f"RPLIDAR response descriptor must be {DESCRIPTOR_SIZE} bytes, got {len(data)}: {data.hex(' ')}")
        if data[0] != SYNC or data[1] != SYNC2:
            raise RplidarProtocolError(f"RPLIDAR response descriptor must start A5 5A, got {data[:2].hex(' ')}")
        word, dtype = struct.unpack_from("<IB", data, 2)
        return cls(length=word & 0x3FFFFFFF, mode=word >> 30, dtype=dtype)


SCAN_DESCRIPTOR = Descriptor(NODE_SIZE, MODE_MULTIPLE, ANS_TYPE_MEASUREMENT)  # A5 5A 05 00 00 40 81
INFO_DESCRIPTOR = Descriptor(INFO_SIZE, MODE_SINGLE, ANS_TYPE_DEVINFO)  # A5 5A 14 00 00 00 04
HEALTH_DESCRIPTOR = Descriptor(HEALTH_SIZE, MODE_SINGLE, ANS_TYPE_DEVHEALTH)  # A5 5A 03 00 00 00 06


def find_descriptor(buf: bytes | bytearray, expected: Descriptor) -> int:
    """Where ``expected``'s 7 bytes start in ``buf`` (-1: not there). The bytes before it are
    leftovers of an earlier session (nodes still in flight after STOP, the boot banner after
    RESET): a reader drops them, which is the descriptor's own resync rule (§2: the fixed
    ``A5 5A`` pattern identifies the start of a response descriptor)."""
    return bytes(buf).find(expected.encode())


@dataclass(frozen=True)
class DeviceInfo:
    """GET_INFO's 20 bytes (Fig. 4-16/4-17)."""

    model: int
    firmware_minor: int
    firmware_major: int
    hardware: int
    serial: bytes  # 16 bytes

    @property
    def firmware(self) -> str:
        return f"{self.firmware_major}.{self.firmware_minor:02d}"

    @property
    def serial_hex(self) -> str:
        """The document prints the serial least significant byte first, i.e. in byte order."""
        return self.serial.hex().upper()

    def encode(self) -> bytes:
        if len(self.serial) != 16:
            raise RplidarProtocolError(f"RPLIDAR serial number must be 16 bytes, got {len(self.serial)}")
        return bytes((self.model, self.firmware_minor, self.firmware_major, self.hardware)) + bytes(self.serial)

    @classmethod
    def decode(cls, data: bytes) -> DeviceInfo:
        if len(data) != INFO_SIZE:
            raise RplidarProtocolError(f"RPLIDAR GET_INFO data must be {INFO_SIZE} bytes, got {len(data)}")
        return cls(data[0], data[1], data[2], data[3], bytes(data[4:20]))


@dataclass(frozen=True)
class Health:
    """GET_HEALTH's 3 bytes (Fig. 4-19/4-20): status, then error_code little-endian."""

    status: int
    error_code: int

    @property
    def name(self) -> str:
        return HEALTH_NAMES.get(self.status, f"unknown status {self.status}")

    def encode(self) -> bytes:
        return struct.pack("<BH", self.status, self.error_code)

    @classmethod
    def decode(cls, data: bytes) -> Health:
        if len(data) != HEALTH_SIZE:
            raise RplidarProtocolError(f"RPLIDAR GET_HEALTH data must be {HEALTH_SIZE} bytes, got {len(data)}")
        status, code = struct.unpack("<BH", data)
        return cls(status, code)


# -- measurement nodes (Fig. 4-4/4-5) ------------------------------------------------------------
@dataclass(frozen=True)
class Nodes:
    """Decoded nodes, one array entry per node."""

    start: np.ndarray  # bool: S, the first node of a new 360 deg scan
    quality: np.ndarray  # uint8, 0..63
    angle_q6: np.ndarray  # uint16, degrees * 64, clockwise
    distance_q2: np.ndarray  # uint16, mm * 4, 0 = invalid

    def __getitem__(self, part: slice) -> Nodes:
        if not isinstance(part, slice):
            raise TypeError(f"Nodes are sliced (nodes[a:b]), not indexed; got {type(part).__name__}")
        return Nodes(self.start[part], self.quality[part], self.angle_q6[part], self.distance_q2[part])

    def __len__(self) -> int:
        return len(self.start)

    @staticmethod
    def empty() -> Nodes:
        return Nodes(np.zeros(0, bool), np.zeros(0, np.uint8), np.zeros(0, np.uint16), np.zeros(0, np.uint16))

    @staticmethod
    def concat(parts: list[Nodes]) -> Nodes:
        if not parts:
            return Nodes.empty()
        if len(parts) == 1:
            return parts[0]
        return Nodes(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("start", "quality", "angle_q6", "distance_q2")))

    @property
    def angle_deg(self) -> np.ndarray:
        return self.angle_q6.astype(np.float64) / 64.0

    @property
    def distance_mm(self) -> np.ndarray:
        return self.distance_q2.astype(np.float64) / 4.0


def encode_nodes(start: np.ndarray, quality: np.ndarray, angle_q6: np.ndarray, distance_q2: np.ndarray) -> bytes:
    """Nodes -> the wire bytes (vectorised). Values out of their fields' ranges are an error."""
    start = np.asarray(start, dtype=bool)
    quality, angle_q6, distance_q2 = (np.asarray(a, dtype=np.int64) for a in (quality, angle_q6, distance_q2))
    n = len(start)
    if not len(quality) == len(angle_q6) == len(distance_q2) == n:
        raise RplidarProtocolError("encode_nodes: start, quality, angle_q6 and distance_q2 must have the same length")
    if n and (quality.min() < 0 or quality.max() > 63):
        raise RplidarProtocolError("encode_nodes: quality must be in 0..63 (6 bits)")
    if n and (angle_q6.min() < 0 or angle_q6.max() >= ANGLE_Q6_FULL):
        raise RplidarProtocolError(f"encode_nodes: angle_q6 must be in [0, {ANGLE_Q6_FULL}) (0..360 deg)")
    if n and (distance_q2.min() < 0 or distance_q2.max() > 0xFFFF):
        raise RplidarProtocolError("encode_nodes: distance_q2 must fit 16 bits")
    out = np.empty((n, NODE_SIZE), dtype=np.uint8)
    s = start.astype(np.int64)
    out[:, 0] = (quality << 2) | ((1 - s) << 1) | s
    out[:, 1] = ((angle_q6 & 0x7F) << 1) | 1  # C = 1
    out[:, 2] = angle_q6 >> 7
    out[:, 3] = distance_q2 & 0xFF
    out[:, 4] = distance_q2 >> 8
    return out.tobytes()


_NODE_DTYPE = np.dtype([("b0", "u1"), ("angle", "<u2"), ("dist", "<u2")])  # packed, 5 bytes
# byte 0 of a node -> 1 if its S / S-bar bits say "start of a new scan" (S=1, S-bar=0), else 0
_START_CANDIDATE = bytes(1 if b & 3 == 1 else 0 for b in range(256))


def _read_only_empty() -> Nodes:
    nodes = Nodes.empty()
    for arr in (nodes.start, nodes.quality, nodes.angle_q6, nodes.distance_q2):
        arr.flags.writeable = False
    return nodes


_EMPTY_NODES = _read_only_empty()  # shared: the parser returns it for "no node yet" (most reads in hold mode)


def _fields(rows: np.ndarray) -> Nodes:
    """Decode (n, 5) node rows: one structured view, no per-byte arithmetic."""
    v = np.ascontiguousarray(rows).view(_NODE_DTYPE).reshape(-1)
    b0 = v["b0"]
    return Nodes(start=(b0 & 1).astype(bool), quality=b0 >> 2, angle_q6=v["angle"] >> 1, distance_q2=v["dist"].copy())


def _angles_at(buf: np.ndarray) -> np.ndarray:
    """angle_q6 read at every offset with 5 bytes after it (int32)."""
    n = len(buf) - NODE_SIZE + 1
    if n <= 0:
        return np.zeros(0, dtype=np.int32)
    return (buf[1:n + 1].astype(np.int32) >> 1) | (buf[2:n + 2].astype(np.int32) << 7)


def node_valid_mask(buf: np.ndarray, angles: np.ndarray | None = None) -> np.ndarray:
    """For every offset i with 5 bytes after it: do bytes i..i+4 pass the node's checks?
    (S xor S-bar == 1, C == 1, angle_q6 < 360 * 64.) ``angles``: ``_angles_at(buf)`` if known."""
    n = len(buf) - NODE_SIZE + 1
    if n <= 0:
        return np.zeros(0, dtype=bool)
    b0, b1 = buf[:n], buf[1:n + 1]
    s_ok = ((b0 ^ (b0 >> 1)) & 1).astype(bool)
    c_ok = (b1 & 1).astype(bool)
    mask: np.ndarray = s_ok & c_ok & ((_angles_at(buf) if angles is None else angles) < ANGLE_Q6_FULL)
    return mask


def decode_nodes(data: bytes) -> Nodes:
    """Decode back-to-back nodes that must all be valid (a strict decoder, for tests and for
    peers that framed the bytes already); :class:`NodeParser` is the stream reader."""
    if len(data) % NODE_SIZE:
        raise RplidarProtocolError(f"decode_nodes: {len(data)} bytes is not a whole number of {NODE_SIZE}-byte nodes")
    rows = np.frombuffer(data, dtype=np.uint8).reshape(-1, NODE_SIZE)
    flat = np.frombuffer(data, dtype=np.uint8)
    ok = node_valid_mask(flat)[::NODE_SIZE] if len(flat) else np.zeros(0, bool)
    if not ok.all():
        bad = int(np.argmin(ok))
        raise RplidarProtocolError(f"decode_nodes: node {bad} ({bytes(rows[bad]).hex(' ')}) fails the S/S-bar/C/angle checks")
    return _fields(rows)


class NodeParser:
    """Streaming reader of SCAN nodes (see the module docstring for the resync rule).

    ``feed(data)`` returns the nodes completed by ``data``; ``dropped`` counts the bytes thrown
    away, ``resyncs`` the times sync was lost. The work per feed is a handful of numpy passes
    over the buffer, whatever its size; Python loops only over sync losses."""

    # Nodes that must pass after a node before it is delivered: its distance bytes (3-4) carry
    # no check bit, so a slip inside them shows only in the alignment of the nodes after it.
    LOOKAHEAD = 2

    def __init__(self, confirm: int = 3, max_step_deg: float | None = 30.0, *, hold_until_start: bool = False,
                 max_hold: int = 4096) -> None:
        if confirm < 1:
            raise ValueError(f"NodeParser: confirm must be >= 1, got {confirm!r}")
        self.confirm = confirm
        # Hold mode (the driver's): in sync, bytes wait, unchecked, until a node that may carry
        # a start flag (S=1, S-bar=0) is among them or ``max_hold`` bytes are waiting; then they
        # are checked in one pass. The checks cost per call far more than per byte (a dozen
        # numpy passes), and a consumer that cuts revolutions needs no node before the next
        # start flag, so a 512-byte read costs one bytes.translate instead of a dozen passes.
        self.hold_until_start = hold_until_start
        self.max_hold = int(max_hold)
        # Samples come in rotation order (Fig. 4-8: one per measurement as the head turns), so
        # two consecutive nodes are a small clockwise step apart (mod 360; ~1 deg on an A1).
        # None turns this plausibility check off and leaves the check bits alone.
        self.max_step = None if max_step_deg is None else int(max_step_deg * 64)
        self._last_angle: int | None = None
        self._lost = False  # sync was lost since the session began
        self._buf = b""
        self._synced = False
        self.dropped = 0
        self.resyncs = 0
        self.nodes = 0
        #: where the last feed dropped bytes: indices into the nodes it returned (a drop at i lies
        #: between node i - 1 and node i), for consumers that mark what a slip may have bent
        self.drop_marks: list[int] = []

    def reset(self) -> None:
        """Forget buffered bytes and sync (a new SCAN session)."""
        self._buf, self._synced, self._last_angle, self._lost = b"", False, None, False

    def _steps_ok(self, prev: np.ndarray, nxt: np.ndarray) -> np.ndarray:
        if self.max_step is None:
            return np.ones(len(nxt), dtype=bool)
        ok: np.ndarray = ((nxt - prev) % ANGLE_Q6_FULL) <= self.max_step
        return ok

    def feed(self, data: bytes) -> Nodes:
        buf = self._buf + bytes(data) if self._buf else bytes(data)
        if self.hold_until_start and self._synced and len(buf) < self.max_hold:
            self.drop_marks = []
            # In sync the buffer starts on a node's first byte: byte 0 of every node is at a
            # multiple of 5. Keep waiting while none of them could be a start node.
            if 1 not in buf[0:len(buf) - len(buf) % NODE_SIZE:NODE_SIZE].translate(_START_CANDIDATE):
                self._buf = buf
                return _EMPTY_NODES
        arr = np.frombuffer(buf, dtype=np.uint8)
        pos = 0
        runs: list[np.ndarray] = []  # structured node rows taken
        taken = 0  # nodes in runs
        self.drop_marks = []
        while True:
            if not self._synced:
                # checks at every byte offset: only while looking for sync
                lock = self._find_lock(arr, pos)
                if lock is None:
                    # keep what could still start a confirmed lock once more bytes arrive
                    keep_from = max(pos, len(buf) - NODE_SIZE * self.confirm + 1)
                    self.dropped += keep_from - pos
                    if keep_from > pos:
                        self.drop_marks.append(taken)
                    pos = keep_from
                    break
                # The first locked candidate is dropped too: bytes slipped in between a node's
                # byte 0 and byte 1 make a candidate of one stray byte plus a real node's angle
                # and distance, which passes every check and aligns the real nodes after it.
                # (Not at a clean start: a session's first byte is a node's first byte.)
                skip = 0 if (lock == pos and not self._lost) else NODE_SIZE
                self.dropped += lock + skip - pos
                if lock + skip > pos:
                    self.drop_marks.append(taken)
                pos = lock + skip
                self._last_angle = (int(arr[lock + 1]) >> 1 | int(arr[lock + 2]) << 7) if skip else None
                self._synced = True
            # In sync: take the nodes at stride 5 up to the first that fails the checks. A node
            # is taken only once LOOKAHEAD nodes after it passed too: the checks live in bytes
            # 0-2, so a node whose tail slipped on the line passes them itself and only the
            # alignment of its successors shows the slip; the nodes right before a failure are
            # therefore dropped as suspect, and the last ones in the buffer wait for successors.
            k = (len(arr) - pos) // NODE_SIZE
            if k == 0:
                break
            rows = arr[pos:pos + k * NODE_SIZE].view(_NODE_DTYPE)
            b0, raw = rows["b0"], rows["angle"]
            ang = (raw >> 1).astype(np.int32)
            ok = (((b0 ^ (b0 >> 1)) & raw & 1) != 0) & (ang < ANGLE_Q6_FULL)
            ok[1:] &= self._steps_ok(ang[:-1], ang[1:])
            if self._last_angle is not None:
                ok[0] &= bool(((int(ang[0]) - self._last_angle) % ANGLE_Q6_FULL) <= (self.max_step or ANGLE_Q6_FULL))
            bad = np.flatnonzero(~ok)
            count = (int(bad[0]) if len(bad) else k) - self.LOOKAHEAD
            if count > 0:
                runs.append(rows[:count])
                taken += count
                pos += count * NODE_SIZE
                self._last_angle = int(ang[count - 1])
            if not len(bad):
                break  # wait for the next node's bytes
            self._synced, self._last_angle, self._lost = False, None, True  # a failed check: drop the suspect, resync
            self.resyncs += 1
            self.dropped += 1
            self.drop_marks.append(taken)
            pos += 1
        self._buf = buf[pos:]
        if not runs:
            return _EMPTY_NODES
        v = runs[0] if len(runs) == 1 else np.concatenate(runs)
        self.nodes += len(v)
        b0 = v["b0"]
        return Nodes(start=(b0 & 1).astype(bool), quality=b0 >> 2, angle_q6=v["angle"] >> 1, distance_q2=v["dist"].copy())

    def _find_lock(self, arr: np.ndarray, pos: int) -> int | None:
        """The first offset >= pos where ``confirm`` candidates 5 bytes apart all pass, each a
        small step after the one before."""
        tail = arr[pos:]
        angles = _angles_at(tail)
        valid = node_valid_mask(tail, angles)
        k = self.confirm
        span = len(valid) - NODE_SIZE * (k - 1)
        if span <= 0:
            return None
        ok = valid[:span].copy()
        for j in range(1, k):
            a, b = NODE_SIZE * j, NODE_SIZE * (j - 1)
            ok &= valid[a:a + span]
            ok &= self._steps_ok(angles[b:b + span], angles[a:a + span])
        hits = np.flatnonzero(ok)
        return pos + int(hits[0]) if len(hits) else None
