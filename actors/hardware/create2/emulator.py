"""A byte-faithful iRobot Create 2 on a pseudo-terminal, over a kinematic 2D world.

It speaks the OI as :mod:`.protocol` cites it: Start/Safe/Full/Stop/Power modes, Drive Direct
(and Drive, PWM treated as Drive Direct), Sensors 142 (single packets 7..58 and group 100),
Query List 149, Stream 148 with Pause/Resume 150 every 15 ms, and it swallows (with their right
lengths) the LED, song and display commands drivers send. Safe mode does what the OI spec's
"Safe" clause says: a cliff or a wheel drop stops the motors and reverts the OI to Passive. In
Passive mode motion commands are ignored.

The base is a kinematic differential drive (``actors/hardware/simworld.py`` puts it in the pybullet
world instead, by overriding ``_advance``): wheel speeds
move toward the commanded ones at ``accel`` m/s^2, the pose integrates exactly per 15 ms tick,
encoders count from wheel travel (508.8 counts per 72 mm-wheel revolution) and wrap at 16
bits; a disc of ``radius`` that would enter an occupied cell of the map does not move and
reports a bump on the side of the contact. The battery drains with the wheel speeds.

"Emulator time" is ``ticks * 0.015 s``: tests measure behaviour in ticks, never in wall time
(``time_scale`` > 1 runs the ticks faster than the wall clock for them).
Unplug = :meth:`unplug` (closes the pty); :meth:`replug` opens a new one and re-points the
stable ``link`` path a driver opens, as a USB adapter re-enumerating under a udev symlink.
"""
from __future__ import annotations

import argparse
import math
import os
import select
import sys
import threading
import time
import tty
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

import numpy as np

from . import protocol as P

if TYPE_CHECKING:
    from emos.actors.nav.maps.grid import OccupancyGridMap

# Bytes that follow each opcode (OI spec, "Commands Quick Reference"); None: variable length.
_ARGS: dict[int, int | None] = {
    P.RESET: 0, P.START: 0, P.BAUD: 1, 130: 0, P.SAFE: 0, P.FULL: 0, P.POWER: 0, 134: 0, 135: 0, 136: 0,
    P.DRIVE: 4, 138: 1, P.LEDS: 3, P.SONG: None, P.PLAY: 1, P.SENSORS: 1, 143: 0, 144: 3,
    P.DRIVE_DIRECT: 4, P.DRIVE_PWM: 4, 147: 1, P.STREAM: None, P.QUERY_LIST: None, P.PAUSE_RESUME_STREAM: 1,
    162: 2, 163: 4, P.DIGIT_LEDS_ASCII: 4, 165: 1, 167: 15, 168: 3, P.STOP: 0,
}


BUMPER_TRAVEL_M = 0.005


def _arg_len(opcode: int, pending: bytes) -> int | None:
    """Argument bytes of ``opcode`` given the bytes after it so far (None: not known yet)."""
    n = _ARGS[opcode]
    if n is not None:
        return n
    if not pending:
        return None
    if opcode == P.SONG:  # [140][song][len][note, duration]*len
        return 2 + 2 * pending[1] if len(pending) >= 2 else None
    return 1 + pending[0]  # Stream / Query List: [n][ids...]


def bump_bits(points: Iterable[Any], x: float, y: float, th: float) -> int:
    """Bumper bits (packet 7) of a body at (x, y, th) touching ``points`` (x, y): the bumper
    covers the front half; contacts within ~6 deg of straight ahead press both sides."""
    bits = 0
    for px, py in points:
        bearing = math.atan2(math.sin(math.atan2(py - y, px - x) - th), math.cos(math.atan2(py - y, px - x) - th))
        if abs(bearing) > math.pi / 2:
            continue  # the bumper covers the front half
        if bearing > -0.1:
            bits |= P.BUMP_LEFT
        if bearing < 0.1:
            bits |= P.BUMP_RIGHT
    return bits


class Create2Emulator:
    """See the module docstring. ``world``: an ``OccupancyGridMap`` (or None: open floor)."""

    def __init__(self, world: OccupancyGridMap | None = None, pose: tuple[float, float, float] = (0.0, 0.0, 0.0), *,
                 link: str | None = None, accel: float = 1.0, radius: float = 0.17,
                 capacity_mah: int = 2696, time_scale: float = 1.0) -> None:
        self.world = world
        self.x, self.y, self.th = (float(v) for v in pose)
        self.link = link
        self.accel = float(accel)
        self.radius = float(radius)
        if not (math.isfinite(time_scale) and time_scale > 0):
            raise ValueError(f"Create2Emulator: time_scale must be a finite factor > 0, got {time_scale!r}")
        self.time_scale = float(time_scale)  # > 1: ticks come faster than the real 15 ms (tests in emulator time)
        self.mode = P.MODE_OFF
        self.ticks = 0
        # None: ticks follow the wall clock, as a real robot's do. An int: the emulator stops at
        # that tick until it is raised, so a test can move robot time in lockstep with a harness
        # and a loaded machine cannot make the robot run ahead of its driver.
        self.tick_limit: int | None = None
        self.cmd_right = self.cmd_left = 0  # mm/s commanded
        self.v_right = self.v_left = 0.0  # m/s actual
        self.counts_left = self.counts_right = 0.0  # cumulative, unwrapped
        self.bumps = 0
        self.wheel_drop = False
        self.cliffs = [False, False, False, False]
        self.capacity_mah = int(capacity_mah)
        self.charge_mah = float(capacity_mah) * 0.9
        self.current_ma = 0
        self.stream_ids: list[int] = []
        self.stream_paused = False
        # (emulator tick, wall perf_counter when the bytes were read, right mm/s, left mm/s)
        self.drive_log: list[tuple[int, float, int, int]] = []
        self.on_drive: Callable[[int, int], None] | None = None
        self.lock = threading.RLock()
        self._rx = bytearray()
        self._master = self._slave = -1
        self.port = ""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._occupied = self._world_points()
        self._open_pty()

    # -- pty ---------------------------------------------------------------------------------------
    def _open_pty(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # bytes 0x11/0x13/0x0d pass unchanged, no echo
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        if self.link:
            tmp = f"{self.link}.tmp{os.getpid()}"
            os.symlink(self.port, tmp)
            os.replace(tmp, self.link)  # atomic: a driver never sees the link missing

    def unplug(self) -> None:
        """Close the pty: the driver's next read/write fails, as when the cable is pulled. The
        robot itself carries on as the real one does: same mode, same last command (it keeps
        driving: nothing but a new command stops a Create 2).

        The link goes with the device, as /dev/ttyUSB0 does: left behind it would name a pty
        number the kernel hands to the next pty opened on this machine, and a driver retrying the
        link would talk to that other device (another test's emulator, two readers on one line)."""
        with self.lock:
            if self.link and os.path.islink(self.link):
                os.unlink(self.link)
            for fd in (self._master, self._slave):
                if fd >= 0:
                    os.close(fd)
            self._master = self._slave = -1

    def replug(self) -> None:
        with self.lock:
            if self._master < 0:
                self._rx.clear()
                self._open_pty()

    @property
    def plugged(self) -> bool:
        return self._master >= 0

    # -- lifecycle ---------------------------------------------------------------------------------
    def start(self) -> Create2Emulator:
        self._thread = threading.Thread(target=self._run, name="create2-emulator", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.unplug()
        if self.link and os.path.islink(self.link):
            os.unlink(self.link)

    def __enter__(self) -> Create2Emulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def time(self) -> float:
        """Emulator time (s): ticks of 15 ms."""
        return self.ticks * P.STREAM_PERIOD_S

    def _run(self) -> None:
        next_tick = time.monotonic()
        while not self._stop.is_set():
            limit = self.tick_limit
            held = limit is not None and self.ticks >= limit
            # Held: keep reading the driver's bytes, poll for the next grant (no busy loop).
            timeout = 0.001 if held else max(0.0, next_tick - time.monotonic())
            master = self._master
            if master >= 0:
                try:
                    ready, _, _ = select.select([master], [], [], timeout)
                except (OSError, ValueError):  # closed by unplug() meanwhile
                    ready = []
                if ready:
                    self._read(master)
            else:
                self._stop.wait(timeout)
            if not held and time.monotonic() >= next_tick:
                self.step()
                next_tick += P.STREAM_PERIOD_S / self.time_scale
                if time.monotonic() - next_tick > 0.5:  # a stalled machine: do not replay seconds at once
                    next_tick = time.monotonic()

    def _read(self, master: int) -> None:
        try:
            data = os.read(master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return
        stamp = time.perf_counter()
        with self.lock:
            self._rx += data
            self._handle_commands(stamp)

    def _write(self, data: bytes) -> None:
        if self._master >= 0:
            try:
                os.write(self._master, data)
            except OSError:  # the driver's side is gone or its buffer is full: the real UART drops too
                pass

    # -- commands ----------------------------------------------------------------------------------
    def feed(self, data: bytes) -> None:
        """Handle command bytes directly (tests of the command parser without a pty)."""
        with self.lock:
            self._rx += data
            self._handle_commands(time.perf_counter())

    def _handle_commands(self, stamp: float) -> None:
        rx = self._rx
        while rx:
            op = rx[0]
            if op not in _ARGS:
                del rx[0]  # not an opcode: the real OI ignores it too
                continue
            n = _arg_len(op, bytes(rx[1:]))
            if n is None or len(rx) < 1 + n:
                return
            args = bytes(rx[1: 1 + n])
            del rx[: 1 + n]
            self._command(op, args, stamp)

    def _command(self, op: int, args: bytes, stamp: float) -> None:
        if op == P.START:
            self.mode = P.MODE_PASSIVE
            return
        if self.mode == P.MODE_OFF:
            return  # OI spec: Start must come first; before it the OI listens to nothing else
        if op in (P.SAFE, 130):
            self.mode = P.MODE_SAFE
        elif op == P.FULL:
            self.mode = P.MODE_FULL
        elif op in (P.POWER, P.RESET):
            self.mode = P.MODE_PASSIVE
            self.cmd_right = self.cmd_left = 0
        elif op == P.STOP:
            self.mode = P.MODE_OFF
            self.cmd_right = self.cmd_left = 0
            self.stream_ids = []
        elif op in (P.DRIVE_DIRECT, P.DRIVE_PWM, P.DRIVE):
            right, left = int.from_bytes(args[0:2], "big", signed=True), int.from_bytes(args[2:4], "big", signed=True)
            if op == P.DRIVE_PWM:  # PWM -255..255 -> a proportional speed
                right, left = right * 500 // 255, left * 500 // 255
            elif op == P.DRIVE:  # [velocity][radius]: straight or spin-in-place cases only
                v, r = right, left
                if r in (1, -1):
                    right, left = (v, -v) if r == 1 else (-v, v)
                else:
                    right = left = v
            self.drive_log.append((self.ticks, stamp, right, left))
            if self.mode in (P.MODE_SAFE, P.MODE_FULL):  # Passive ignores actuator commands
                self.cmd_right = max(-500, min(500, right))
                self.cmd_left = max(-500, min(500, left))
            if self.on_drive is not None:
                self.on_drive(right, left)
        elif op == P.SENSORS:
            self._write(self._packet_bytes(args[0]))
        elif op == P.QUERY_LIST:
            self._write(b"".join(self._packet_bytes(pid) for pid in args[1:]))
        elif op == P.STREAM:
            self.stream_ids = [pid for pid in args[1:] if pid in P.PACKET_FORMATS]
            self.stream_paused = False
        elif op == P.PAUSE_RESUME_STREAM:
            self.stream_paused = args[0] == 0

    def _packet_bytes(self, pid: int) -> bytes:
        values = self.sensor_values()
        if pid == P.PKT_GROUP_ALL:
            return P.encode_group_100(values)
        if pid in P.PACKET_FORMATS:
            return P.encode_values({pid: values.get(pid, 0)})[pid]
        return b""

    # -- sensors -----------------------------------------------------------------------------------
    def sensor_values(self) -> dict[int, int]:
        def wrap16(c: float) -> int:
            return ((int(math.floor(c)) + 0x8000) & 0xFFFF) - 0x8000  # signed 16, rolls over (packet 43)

        frac = self.charge_mah / max(1, self.capacity_mah)
        return {
            P.PKT_BUMPS_WHEELDROPS: self.bumps | ((P.WHEELDROP_LEFT | P.WHEELDROP_RIGHT) if self.wheel_drop else 0),
            P.PKT_CLIFF_LEFT: int(self.cliffs[0]), P.PKT_CLIFF_FRONT_LEFT: int(self.cliffs[1]),
            P.PKT_CLIFF_FRONT_RIGHT: int(self.cliffs[2]), P.PKT_CLIFF_RIGHT: int(self.cliffs[3]),
            P.PKT_CHARGING_STATE: 0, P.PKT_VOLTAGE: int(13000 + 3000 * frac), P.PKT_CURRENT: int(self.current_ma),
            P.PKT_TEMPERATURE: 25, P.PKT_CHARGE: int(self.charge_mah), P.PKT_CAPACITY: self.capacity_mah,
            P.PKT_OI_MODE: self.mode, 41: self.cmd_right, 42: self.cmd_left, 39: (self.cmd_right + self.cmd_left) // 2,
            P.PKT_ENCODER_LEFT: wrap16(self.counts_left), P.PKT_ENCODER_RIGHT: wrap16(self.counts_right),
        }

    def set_wheel_drop(self, dropped: bool) -> None:
        with self.lock:
            self.wheel_drop = dropped

    def set_cliff(self, index: int, cliff: bool) -> None:
        with self.lock:
            self.cliffs[index] = cliff

    # -- world -------------------------------------------------------------------------------------
    def _world_points(self) -> np.ndarray:
        if self.world is None:
            return np.zeros((0, 2))
        grid = self.world
        iy, ix = np.nonzero(np.asarray(grid.data) >= 65)  # map_server's occupied threshold (0.65)
        return np.asarray(grid.grid_to_world(np.stack([ix, iy], axis=1)), dtype=np.float64).reshape(-1, 2)

    def _contacts(self, x: float, y: float, radius: float | None = None) -> np.ndarray:
        """Occupied points within ``radius`` (default: the body's) of (x, y)."""
        pts = self._occupied
        if not len(pts):
            return pts
        r = self.radius if radius is None else radius
        d2 = (pts[:, 0] - x) ** 2 + (pts[:, 1] - y) ** 2
        return pts[d2 <= r * r]

    def add_obstacle(self, x: float, y: float) -> None:
        """A point obstacle (a chair leg) for tests on open floor."""
        with self.lock:
            self._occupied = np.vstack([self._occupied, [[x, y]]])

    # -- physics -----------------------------------------------------------------------------------
    def step(self) -> None:
        """One 15 ms tick: wheels, pose, encoders, bumps, safety, battery, the stream frame."""
        dt = P.STREAM_PERIOD_S
        with self.lock:
            self.ticks += 1
            if self.mode == P.MODE_SAFE and (self.wheel_drop or any(self.cliffs)):
                # OI spec, Safe mode: a cliff or wheel drop stops the motors and reverts to Passive.
                self.cmd_right = self.cmd_left = 0
                self.v_right = self.v_left = 0.0
                self.mode = P.MODE_PASSIVE
            dv = self.accel * dt
            for side in ("right", "left"):
                target = getattr(self, f"cmd_{side}") / 1000.0
                v = getattr(self, f"v_{side}")
                setattr(self, f"v_{side}", v + max(-dv, min(dv, target - v)))
            dr, dl = self._advance(self.v_right * dt, self.v_left * dt, dt)
            self.counts_right += dr / P.M_PER_COUNT
            self.counts_left += dl / P.M_PER_COUNT
            self.current_ma = -int(300 + 0.8 * (abs(self.cmd_right) + abs(self.cmd_left)))
            self.charge_mah = max(0.0, self.charge_mah + self.current_ma * dt / 3600.0)
            if self.stream_ids and not self.stream_paused and self.mode != P.MODE_OFF:
                values = self.sensor_values()
                self._write(P.encode_frame({pid: values.get(pid, 0) for pid in self.stream_ids}, self.stream_ids))

    def _advance(self, dr: float, dl: float, dt: float) -> tuple[float, float]:
        """Move the body by the wheels' travel (m) this tick and set ``bumps``; return the travel
        the encoders count. Kinematic here; ``actors/hardware/simworld.py`` moves a pybullet body."""
        ds, dth = (dr + dl) / 2.0, (dr - dl) / P.WHEEL_BASE_M
        mid = self.th + dth / 2.0
        nx, ny = self.x + ds * math.cos(mid), self.y + ds * math.sin(mid)
        if ds != 0.0 and self._moves_into(nx, ny):
            # pushing into the obstacle: the wheels slip, nothing moves, encoders stand still
            dr = dl = 0.0
        else:
            self.x, self.y = nx, ny
            self.th = math.atan2(math.sin(self.th + dth), math.cos(self.th + dth))
        # The bumper is pressed while the front half touches something (its ~5 mm travel).
        self.bumps = self._bump_bits(self.x, self.y, self.th, self.radius + BUMPER_TRAVEL_M)
        return dr, dl

    def _bump_bits(self, x: float, y: float, th: float, radius: float) -> int:
        return bump_bits(self._contacts(x, y, radius), x, y, th)

    def _moves_into(self, nx: float, ny: float) -> bool:
        """Does the step bring the body closer to what it touches?"""
        pts = self._contacts(nx, ny)
        if not len(pts):
            return False
        before = np.min((pts[:, 0] - self.x) ** 2 + (pts[:, 1] - self.y) ** 2)
        after = np.min((pts[:, 0] - nx) ** 2 + (pts[:, 1] - ny) ** 2)
        return bool(after < before)

    def truth(self) -> tuple[float, float, float]:
        with self.lock:
            return self.x, self.y, self.th


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m emos.actors.hardware.create2.emulator",
                                     description="An emulated iRobot Create 2 on a pseudo-terminal (kinematic 2D base).")
    parser.add_argument("--map", help="a ROS map YAML (its PGM next to it): the obstacles the bumper feels")
    parser.add_argument("--pose", default="0,0,0", help="start pose x,y,theta (m, m, rad)")
    parser.add_argument("--link", help="also make this path a symlink to the pty (stable across replugs)")
    args = parser.parse_args(argv)
    try:
        pose = tuple(float(v) for v in args.pose.split(","))
        if len(pose) != 3 or not all(math.isfinite(v) for v in pose):
            raise ValueError
    except ValueError:
        parser.error(f"--pose: expected three finite numbers x,y,theta, got {args.pose!r}")
    world = None
    if args.map:
        from emos.actors.nav.maps.map_yaml import load_map
        world = load_map(args.map)
    emu = Create2Emulator(world, (pose[0], pose[1], pose[2]), link=args.link)
    print(args.link or emu.port, flush=True)
    emu.start()
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        emu.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
