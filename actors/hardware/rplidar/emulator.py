"""A byte-faithful RPLIDAR A1/A2 on a pseudo-terminal, whose ranges come from a 2D world.

The emulator answers the requests of the protocol document (see ``protocol.py`` for the
clauses) on the master side of a pty; a driver opens the slave side as it would open
``/dev/ttyUSB0``. Quirks kept from the real device:

* SCAN answers its descriptor at once, but nodes flow "only after the motor rotation becomes
  stable": the motor takes ``spin_up_s`` to reach speed after it is started (A2: by
  SET_MOTOR_PWM > 0; A1: by its USB adapter's DTR line, which a pty does not carry, so an A1
  emulator starts its motor at the first SCAN).
* revolutions of ``points_per_rev`` nodes at ``rev_hz``; the first node of each has S=1; the
  angles of a revolution start at a random fraction of a step (a real motor does not land on
  the same angles twice); quality falls with range and is 0 with distance 0 for no return.
* any new request ends a scan (the device "will leave the Scanning state once it receives a
  new request"); RESET prints the boot banner text a real A1 prints before it is idle again.
* the device just sends: when the host does not read, the pty's buffer fills and bytes are
  lost (counted in ``bytes_lost``), as a UART overrun loses them.

``unplug()`` closes the pty (the driver's reads fail as on a USB unplug) and ``replug()`` opens a
new one; give ``link`` (a path) so the port keeps its name across replugs, as a udev
``/dev/serial/by-id`` link does. The pty is not paced at 115200 baud: a 360-point 10 Hz stream
(18 kB/s) is more than that line carries, and the brief asks for the A1's 10 Hz x 360 points.

Ranges: ``source(pose, bearings) -> ranges`` (metres, ``inf`` = no return) with ``bearings`` in
the sensor frame in the ROS convention (counter-clockwise, radians); :class:`MapRaycaster` is
one made from a ROS map YAML + image. ``python -m emos.actors.hardware.rplidar.emulator --map
FILE --pose x,y,th`` runs one and prints its port.
"""
from __future__ import annotations

import argparse
import contextlib
import errno
import math
import os
import select
import signal
import struct
import sys
import threading
import time
import tty
from collections.abc import Callable
from pathlib import Path

import numpy as np

from . import protocol as P

__all__ = ["RangeSource", "MapRaycaster", "cast_ranges", "RplidarEmulator", "main"]

RangeSource = Callable[[tuple[float, float, float], np.ndarray], np.ndarray]

BOOT_BANNER = b"RP LIDAR System.\r\nFirmware Ver 1.29 - rtm, HW Ver 7\r\nModel: 18\r\n"


def cast_ranges(grid, pose: tuple[float, float, float], bearings: np.ndarray, max_range: float) -> np.ndarray:
    """Ranges a perfect 2D laser at ``pose`` (x, y, yaw in the map frame) measures along
    ``bearings`` (sensor frame, counter-clockwise): the distance to the first occupied cell
    (value >= 65, or outside the map), marched in quarter-cell steps; ``inf`` past ``max_range``."""
    res = float(grid.resolution)
    steps = np.arange(res / 4.0, max_range + res / 4.0, res / 4.0)
    th = pose[2] + np.asarray(bearings, dtype=np.float64)
    x = pose[0] + np.cos(th)[:, None] * steps
    y = pose[1] + np.sin(th)[:, None] * steps
    occ = grid.values_at(np.stack([x, y], axis=-1), outside=100) >= 65
    hit = occ.any(axis=1)
    out = np.full(len(th), np.inf)
    out[hit] = steps[occ.argmax(axis=1)[hit]]
    out[out > max_range] = np.inf
    return out


class MapRaycaster:
    """A :data:`RangeSource` over a ROS map (``map_yaml``: path of the map_server YAML)."""

    def __init__(self, map_yaml: str | os.PathLike, max_range: float = 12.0) -> None:
        from emos.actors.nav.maps import load_map

        self.grid = load_map(map_yaml)
        self.max_range = float(max_range)

    def __call__(self, pose: tuple[float, float, float], bearings: np.ndarray) -> np.ndarray:
        return cast_ranges(self.grid, pose, bearings, self.max_range)


class RplidarEmulator:
    """An RPLIDAR on a pty (module docstring). Start with ``start()`` (or ``with``); ``path`` is the
    port to open."""

    def __init__(self, source: RangeSource, pose: tuple[float, float, float] = (0.0, 0.0, 0.0), *, model: str = "A1",
                 points_per_rev: int = 360, rev_hz: float = 10.0, spin_up_s: float = 0.4, range_max: float = 12.0,
                 health: P.Health | None = None, link: str | os.PathLike | None = None,
                 seed: int = 0) -> None:
        if model not in ("A1", "A2"):
            raise ValueError(f"RplidarEmulator: model must be 'A1' or 'A2', got {model!r}")
        if points_per_rev < 8 or not rev_hz > 0 or spin_up_s < 0:
            raise ValueError("RplidarEmulator: points_per_rev >= 8, rev_hz > 0 and spin_up_s >= 0 are required")
        self.source = source
        self._pose = tuple(float(v) for v in pose)
        self.model = model
        self.points_per_rev = int(points_per_rev)
        self.rev_hz = float(rev_hz)
        self.spin_up_s = float(spin_up_s)
        self.range_max = float(range_max)
        self.health = health if health is not None else P.Health(P.HEALTH_GOOD, 0)
        self.info = P.DeviceInfo(model=0x18 if model == "A1" else 0x28, firmware_minor=29, firmware_major=1, hardware=7,
                                 serial=bytes(range(0x10, 0x20)))
        self.link = Path(link) if link is not None else None
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._pending_garbage = b""
        self._master = self._slave = -1
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.bytes_lost = 0
        self.nodes_sent = 0
        self.revolutions_sent = 0
        self.requests: list[tuple[int, bytes]] = []  # (cmd, payload) of every valid request, for tests
        self.bad_checksums = 0

    # -- pose and faults ------------------------------------------------------------------------
    @property
    def pose(self) -> tuple[float, float, float]:
        with self._lock:
            return self._pose  # type: ignore[return-value]

    @pose.setter
    def pose(self, value: tuple[float, float, float]) -> None:
        with self._lock:
            self._pose = tuple(float(v) for v in value)

    def inject(self, data: bytes) -> None:
        """Send ``data`` (garbage, a partial node) between two node writes of the stream."""
        with self._lock:
            self._pending_garbage += bytes(data)

    # -- the pty ----------------------------------------------------------------------------------
    @property
    def path(self) -> str:
        if self.link is not None:
            return str(self.link)
        if self._slave < 0:
            raise RuntimeError("RplidarEmulator: not started (no pty yet)")
        return os.ttyname(self._slave)

    def start(self) -> RplidarEmulator:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line editing: the line carries bytes, as a UART does
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        if self.link is not None:
            with contextlib.suppress(FileNotFoundError):
                self.link.unlink()
            self.link.symlink_to(os.ttyname(slave))
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="rplidar-emulator", daemon=True)
        self._thread.start()
        return self

    def unplug(self) -> None:
        """Close the pty: the device vanishes (the driver's next read fails)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1
        if self.link is not None:
            with contextlib.suppress(FileNotFoundError):
                self.link.unlink()

    def replug(self) -> None:
        """A new pty (the link, if any, points at it): a device powered up again, idle."""
        self.unplug()
        self.start()

    close = unplug

    def __enter__(self) -> RplidarEmulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.unplug()

    # -- the device -------------------------------------------------------------------------------
    def _run(self) -> None:
        rx = b""
        scanning = False
        motor_since: float | None = None  # when the motor was started (None: stopped)
        stream_t0 = 0.0
        sent = 0  # samples sent since the stream began
        rev_ranges = np.zeros(0)
        rev_offset = 0.0
        master = self._master
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([master], [], [], 0.005)
            except (OSError, ValueError):
                return
            if ready:
                try:
                    chunk = os.read(master, 4096)
                except BlockingIOError:
                    chunk = b""
                except OSError as exc:
                    if exc.errno == errno.EIO:  # no one has the slave open right now
                        time.sleep(0.005)
                        continue
                    return
                rx += chunk
                rx, reqs = self._split_requests(rx)
                for cmd, payload in reqs:
                    self.requests.append((cmd, payload))
                    scanning = False  # any new request ends a scan session
                    if cmd == P.CMD_GET_INFO:
                        self._write(P.INFO_DESCRIPTOR.encode() + self.info.encode())
                    elif cmd == P.CMD_GET_HEALTH:
                        self._write(P.HEALTH_DESCRIPTOR.encode() + self.health.encode())
                    elif cmd in (P.CMD_SCAN, P.CMD_FORCE_SCAN):
                        self._write(P.SCAN_DESCRIPTOR.encode())
                        if self.health.status == P.HEALTH_ERROR:
                            continue  # "ignored when RPLIDAR is in the Protection Stop state"
                        scanning, sent = True, 0
                        if self.model == "A1" and motor_since is None:
                            motor_since = time.monotonic()
                        stream_t0 = max(time.monotonic(), (motor_since or 0.0) + self.spin_up_s)
                    elif cmd == P.CMD_SET_MOTOR_PWM and len(payload) == 2:
                        pwm = struct.unpack("<H", payload)[0]
                        if pwm == 0:
                            motor_since = None
                        elif motor_since is None:
                            motor_since = time.monotonic()
                    elif cmd == P.CMD_RESET:
                        motor_since = None
                        time.sleep(0.002)
                        self._write(BOOT_BANNER)
            if not scanning or motor_since is None:
                continue
            now = time.monotonic()
            if now < stream_t0:
                continue  # the motor is still spinning up: the descriptor is out, no nodes yet
            n = self.points_per_rev
            due = min(int((now - stream_t0) * self.rev_hz * n) - sent, n)  # at most a revolution per pass
            if due <= 0:
                continue
            parts = []
            while due > 0:
                i = sent % n
                if i == 0 or len(rev_ranges) != n:
                    rev_offset = float(self._rng.uniform(0.0, 360.0 / n))
                    cw_deg = rev_offset + np.arange(n) * (360.0 / n)
                    rev_ranges = np.asarray(self.source(self.pose, -np.radians(cw_deg)), dtype=np.float64)
                take = min(due, n - i)
                idx = np.arange(i, i + take)
                cw = rev_offset + idx * (360.0 / n)
                r = rev_ranges[idx]
                ok = np.isfinite(r) & (r > 0) & (r <= self.range_max)
                dist = np.where(ok, np.clip(np.rint(np.where(ok, r, 0.0) * 4000.0), 1, 0xFFFF), 0)
                quality = np.where(ok, np.clip(np.rint(60.0 - 3.0 * np.where(ok, r, 0.0)), 10, 63), 0)
                parts.append(P.encode_nodes(idx == 0, quality, np.minimum(np.rint(cw * 64.0), P.ANGLE_Q6_FULL - 1), dist))
                self.revolutions_sent += int(i == 0)
                sent += take
                due -= take
                self.nodes_sent += take
            with self._lock:
                garbage, self._pending_garbage = self._pending_garbage, b""
            data = b"".join(parts)
            if garbage:
                cut = len(data) // 2
                data = data[:cut] + garbage + data[cut:]
            self._write(data)

    def _split_requests(self, rx: bytes) -> tuple[bytes, list[tuple[int, bytes]]]:
        """Complete requests in ``rx`` (§2: ``A5 cmd`` or, for cmd >= 0x80, ``A5 cmd size payload
        checksum``); a request with a bad checksum is discarded, as the device does."""
        out: list[tuple[int, bytes]] = []
        while True:
            start = rx.find(bytes((P.SYNC,)))
            if start < 0:
                return b"", out
            rx = rx[start:]
            if len(rx) < 2:
                return rx, out
            cmd = rx[1]
            if not cmd & 0x80:
                out.append((cmd, b""))
                rx = rx[2:]
                continue
            if len(rx) < 3 or len(rx) < 4 + rx[2]:
                return rx, out
            size = rx[2]
            packet, rx = rx[:4 + size], rx[4 + size:]
            if P.checksum(packet[:-1]) != packet[-1]:
                self.bad_checksums += 1
                continue
            out.append((cmd, packet[3:3 + size]))

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(self._master, view)
            except BlockingIOError:
                self.bytes_lost += len(view)  # the host is not reading: a UART overrun
                return
            except OSError:
                return
            view = view[n:]


def _pose(text: str) -> tuple[float, float, float]:
    parts = text.split(",")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"--pose must be x,y,theta (metres, metres, radians), got {text!r}")
    try:
        x, y, th = (float(p) for p in parts)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--pose must be three numbers x,y,theta, got {text!r}") from exc
    if not all(math.isfinite(v) for v in (x, y, th)):
        raise argparse.ArgumentTypeError(f"--pose must be finite, got {text!r}")
    return x, y, th


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m emos.actors.hardware.rplidar.emulator",
                                 description="An emulated RPLIDAR A1/A2 on a pseudo-terminal, ray-casting a ROS map.")
    ap.add_argument("--map", required=True, help="map_server YAML (with its PGM/PNG image)")
    ap.add_argument("--pose", required=True, type=_pose, help="x,y,theta of the lidar in the map frame")
    ap.add_argument("--model", choices=("A1", "A2"), default="A1")
    ap.add_argument("--hz", type=float, default=10.0, help="revolutions per second")
    ap.add_argument("--points", type=int, default=360, help="nodes per revolution")
    ap.add_argument("--link", default=None, help="also make this symlink to the pty (a stable port name)")
    args = ap.parse_args(argv)
    emu = RplidarEmulator(MapRaycaster(args.map), args.pose, model=args.model, rev_hz=args.hz,
                          points_per_rev=args.points, link=args.link)
    emu.start()
    print(emu.path, flush=True)
    done = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: done.set())
    done.wait()
    emu.unplug()
    return 0


if __name__ == "__main__":
    sys.exit(main())
