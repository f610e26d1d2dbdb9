"""A byte-faithful Feetech STS3215 bus emulator on a pseudo-terminal.

    python -m emos.actors.hardware.feetech.emulator --ids 1,2,3,4,5,6

prints the path to open (a symlink to the current pty, as ``/dev/serial/by-id/...`` is for a real
USB adapter) and serves the protocol of :mod:`.protocol` on it until interrupted.

Each servo has its control table in memory (the registers of :class:`.protocol.Reg` with the
STS3215's factory values: model 777, return delay 250 = 500 us, 7.4 V, 25 deg C). The motion is a
kinematic model here (:mod:`.simarm` swaps in the pybullet arm through ``servo_factory``, the bus
untouched): with torque on, the present
position moves toward the goal position at the goal speed, capped at the STS3215's no-load
speed of 0.222 s / 60 deg at 7.4 V (Feetech's data sheet: 4.71 rad/s = 3072 steps/s),
acceleration taken as instant. Timing is honest for the bus: a servo answers after its Return
Delay Time register (2 us units) plus the wire time of its answer at the baud rate (10 bits per
byte); the servos of a SYNC_READ answer one after the other in the order asked.

For tests: :meth:`BusEmulator.set_silent` makes a servo ignore the bus, :meth:`unplug` closes the
pty (the driver's port goes dead, the path disappears) and :meth:`replug` opens a new pty behind
the same path. :attr:`BusEmulator.bad_packets` counts the bytes the emulator's parser dropped.
"""
from __future__ import annotations

import argparse
import os
import select
import signal
import sys
import tempfile
import threading
import time
import tty
from collections.abc import Callable, Iterable
from typing import Any

from . import protocol as P
from .protocol import Instruction, Reg

WIRE_BITS_PER_BYTE = 10  # 8N1: start + 8 data + stop


class ServoModel:
    """One STS3215: its control table and a kinematic motor (module docstring)."""

    def __init__(self, servo_id: int, *, position: int = 2048, clock: Callable[[], float] = time.monotonic) -> None:
        if not 0 <= servo_id <= P.MAX_ID:
            raise ValueError(f"servo id must be 0..{P.MAX_ID}, got {servo_id}")
        self.clock = clock
        self.table = bytearray(P.TABLE_SIZE)
        self._put(Reg.MODEL_NUMBER, P.STS3215_MODEL)
        self._put(Reg.ID, servo_id)
        self._put(Reg.BAUD_RATE, 0)  # 0 = 1 Mbaud in the STS baud table
        self._put(Reg.RETURN_DELAY_TIME, 250)
        self._put(Reg.STATUS_RETURN_LEVEL, 1)
        self._put(Reg.MAX_POSITION_LIMIT, P.STEPS_PER_TURN - 1)
        self._put(Reg.LOCK, 1)
        self._put(Reg.PRESENT_VOLTAGE, 74)
        self._put(Reg.PRESENT_TEMPERATURE, 25)
        self.position = float(position)  # steps, kept fractional between updates
        self._put(Reg.GOAL_POSITION, position)
        self._put(Reg.PRESENT_POSITION, position)
        self._last = clock()
        self.silent = False

    @property
    def id(self) -> int:
        return self.table[Reg.ID.address]

    def _put(self, reg: P.Register, value: int) -> None:
        self.table[reg.address: reg.address + reg.size] = P.encode_value(reg, value)

    def get(self, reg: P.Register) -> int:
        return P.decode_value(reg, bytes(self.table[reg.address: reg.address + reg.size]))

    @property
    def speed_limit(self) -> float:
        """Steps/s this servo moves at now: the goal speed, 0 meaning (and capped at) the maximum."""
        goal = abs(self.get(Reg.GOAL_SPEED))
        return float(P.MAX_SPEED_STEPS_PER_S if goal == 0 else min(goal, P.MAX_SPEED_STEPS_PER_S))

    def update(self, now: float | None = None) -> None:
        """Move the motor from the last update to ``now``."""
        now = self.clock() if now is None else now
        if now <= self._last:
            return  # no time passed: nothing moved (and the speed stays what it was)
        dt, self._last = now - self._last, now
        speed, moving = 0.0, False
        if self.table[Reg.TORQUE_ENABLE.address]:
            lo, hi = self.get(Reg.MIN_POSITION_LIMIT), self.get(Reg.MAX_POSITION_LIMIT)
            goal = min(max(self.get(Reg.GOAL_POSITION), lo), hi)
            error = goal - self.position
            step = min(abs(error), self.speed_limit * dt)
            if step > 0:
                self.position += step if error > 0 else -step
                speed = (step / dt if dt > 0 else 0.0) * (1 if error > 0 else -1)
            moving = abs(goal - self.position) >= 0.5  # not there yet
        present = int(round(self.position)) % P.STEPS_PER_TURN
        self._put(Reg.PRESENT_POSITION, present)
        self._put(Reg.PRESENT_SPEED, int(round(speed)))
        self.table[Reg.MOVING.address] = 1 if moving else 0

    def read(self, address: int, length: int) -> bytes | None:
        if length < 1 or address + length > P.TABLE_SIZE:
            return None
        self.update()
        return bytes(self.table[address: address + length])

    def write(self, address: int, data: bytes) -> bool:
        if not data or address + len(data) > P.TABLE_SIZE:
            return False
        self.update()  # the motion so far happened under the old goal
        for offset, byte in enumerate(data):
            addr = address + offset
            if addr < Reg.ID.address or Reg.PRESENT_POSITION.address <= addr < 70:
                continue  # read-only: version/model numbers and the present-state registers
            self.table[addr] = byte
        return True


class BusEmulator:
    """N servos on one emulated bus behind a pty (module docstring)."""

    def __init__(self, ids: Iterable[int] = (1, 2, 3, 4, 5, 6), *, baudrate: int = 1_000_000,
                 return_delay: int | None = None, link_dir: str | None = None,
                 servo_factory: Callable[[int], ServoModel] = ServoModel) -> None:
        ids = list(ids)
        if not ids or len(set(ids)) != len(ids):
            raise ValueError(f"emulator needs distinct servo ids, got {ids}")
        # servo_factory(id) builds each servo: the motion model is swappable (simarm.PybulletServo)
        self.servos = {i: servo_factory(i) for i in ids}
        if return_delay is not None:
            for servo in self.servos.values():
                servo.table[Reg.RETURN_DELAY_TIME.address] = return_delay
        self.byte_time = WIRE_BITS_PER_BYTE / float(baudrate)
        self._lock = threading.Lock()
        self._dir = tempfile.mkdtemp(prefix="emos-feetech-", dir=link_dir)
        self.path = os.path.join(self._dir, "ttyFEETECH")  # stable across unplug/replug
        self._master = -1
        self._slave = -1
        self._wake_r, self._wake_w = os.pipe()
        self._stop = threading.Event()
        self._parser = P.PacketParser(status=False)
        self.instructions = 0
        self._noise = b""
        self._thread: threading.Thread | None = None
        self._plug()

    # -- the pty ---------------------------------------------------------------------------------
    def _plug(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line discipline: bytes pass as they are
        self._master, self._slave = master, slave
        tmp = self.path + ".new"
        if os.path.lexists(tmp):
            os.unlink(tmp)
        os.symlink(os.ttyname(slave), tmp)
        os.replace(tmp, self.path)
        self._parser = P.PacketParser(status=False)

    @property
    def bad_packets(self) -> int:
        return self._parser.dropped

    def start(self) -> BusEmulator:
        self._thread = threading.Thread(target=self._serve, name="feetech-emulator", daemon=True)
        self._thread.start()
        return self

    def unplug(self) -> None:
        """The USB adapter is pulled: the pty closes (the driver's reads and writes fail), the path goes."""
        with self._lock:
            if os.path.lexists(self.path):
                os.unlink(self.path)
            for fd in (self._master, self._slave):
                if fd >= 0:
                    os.close(fd)
            self._master = self._slave = -1
        os.write(self._wake_w, b"x")

    def replug(self) -> None:
        with self._lock:
            if self._master < 0:
                self._plug()
        os.write(self._wake_w, b"x")

    def set_silent(self, servo_id: int, silent: bool = True) -> None:
        self.servos[servo_id].silent = silent

    def glitch_next_answer(self, noise: bytes) -> None:
        """Line noise: ``noise`` goes out just before the next answer's bytes."""
        self._noise = bytes(noise)

    def close(self) -> None:
        self._stop.set()
        os.write(self._wake_w, b"x")
        if self._thread is not None:
            self._thread.join(5.0)
        self.unplug()
        for fd in (self._wake_r, self._wake_w):
            os.close(fd)
        try:
            os.rmdir(self._dir)
        except OSError:
            pass

    def __enter__(self) -> BusEmulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- serving ---------------------------------------------------------------------------------
    def _serve(self) -> None:
        while not self._stop.is_set():
            master = self._master
            fds = [self._wake_r] + ([master] if master >= 0 else [])
            try:
                ready, _, _ = select.select(fds, [], [], 1.0)
            except (OSError, ValueError):
                continue  # unplug() closed the pty under this select: look again
            if self._wake_r in ready:
                os.read(self._wake_r, 64)
                continue
            if master not in ready:
                continue
            with self._lock:
                if master != self._master:
                    continue
                try:
                    data = os.read(master, 4096)
                except OSError:
                    continue  # the pty is being closed
                for packet in self._parser.feed(data):
                    self.instructions += 1
                    self._handle(packet)

    def _handle(self, packet: P.Packet) -> None:
        """Answer one instruction packet; the answers go out with the bus's timing."""
        # Every instruction first arrives over the wire; the servos act on its last byte.
        answers: list[tuple[ServoModel, bytes]] = []
        instr, params = packet.code, packet.params
        if instr == Instruction.SYNC_READ and packet.id == P.BROADCAST_ID and len(params) >= 2:
            address, length = params[0], params[1]
            for servo_id in params[2:]:
                servo = self.servos.get(servo_id)
                if servo is not None and not servo.silent:
                    data = servo.read(address, length)
                    if data is not None:
                        answers.append((servo, P.status(servo_id, 0, data)))
        elif instr == Instruction.SYNC_WRITE and packet.id == P.BROADCAST_ID and len(params) >= 2:
            address, length = params[0], params[1]
            body = params[2:]
            if length and len(body) % (length + 1) == 0:
                for k in range(0, len(body), length + 1):
                    servo = self.servos.get(body[k])
                    if servo is not None and not servo.silent:
                        servo.write(address, body[k + 1: k + 1 + length])
        else:
            targets = list(self.servos.values()) if packet.id == P.BROADCAST_ID else [s for s in [self.servos.get(packet.id)] if s]
            for servo in targets:
                if servo.silent:
                    continue
                answer = self._answer(servo, instr, params)
                if answer is not None and packet.id != P.BROADCAST_ID:  # broadcast: nobody answers
                    answers.append((servo, answer))
        self._send(answers, 6 + len(params))

    def _answer(self, servo: ServoModel, instr: int, params: bytes) -> bytes | None:
        replies_all = servo.table[Reg.STATUS_RETURN_LEVEL.address] != 0
        if instr == Instruction.PING:
            return P.status(servo.id)
        if instr == Instruction.READ and len(params) == 2:
            data = servo.read(params[0], params[1])
            return None if data is None else P.status(servo.id, 0, data)
        if instr == Instruction.WRITE and len(params) >= 2:
            ok = servo.write(params[0], params[1:])
            return P.status(servo.id) if ok and replies_all else None
        return None  # unknown or malformed: a real servo stays silent

    def _send(self, answers: list[tuple[ServoModel, bytes]], asked_bytes: int) -> None:
        """The instruction's own wire time (a pty delivers it at once), then each servo waits its
        return delay after the bus went quiet and its bytes take their wire time."""
        due = time.monotonic() + asked_bytes * self.byte_time
        for servo, answer in answers:
            due += servo.table[Reg.RETURN_DELAY_TIME.address] * 2e-6 + len(answer) * self.byte_time
            pause = due - time.monotonic()
            if pause > 0:
                time.sleep(pause)
            noise, self._noise = self._noise, b""
            try:
                os.write(self._master, noise + answer)
            except OSError:
                return  # unplugged mid-answer


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m emos.actors.hardware.feetech.emulator",
                                     description="Emulate a Feetech STS3215 servo bus on a pseudo-terminal.")
    parser.add_argument("--ids", default="1,2,3,4,5,6", help="comma-separated servo ids (default 1..6)")
    parser.add_argument("--baudrate", type=int, default=1_000_000)
    parser.add_argument("--return-delay", type=int, default=None,
                        help="Return Delay Time register (2 us units; default the factory 250)")
    args = parser.parse_args(argv)
    try:
        ids = [int(x) for x in args.ids.split(",") if x.strip()]
    except ValueError:
        parser.error(f"--ids: expected comma-separated integers, got {args.ids!r}")
    emu = BusEmulator(ids, baudrate=args.baudrate, return_delay=args.return_delay)
    return serve_until_stopped(emu, f"Feetech bus emulator: servos {ids}")


def serve_until_stopped(bus: Any, what: str) -> int:
    """Open ``bus`` (a context manager with a ``path``: the emulator, or the arm driving one),
    print its path on stdout (alone, for scripts) and ``what`` on stderr, and serve until
    SIGTERM or Ctrl-C; the bus is closed on either."""
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    with bus:
        print(bus.path, flush=True)
        print(f"{what} on {bus.path} -> {os.path.realpath(bus.path)}; Ctrl-C stops", file=sys.stderr, flush=True)
        try:
            stop.wait()
        except KeyboardInterrupt:
            pass
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
