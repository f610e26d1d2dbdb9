"""RPLIDAR A1/A2 driver over pyserial: start-up checks, the scan stream, and reconnection.

``RplidarDriver(port).start()`` opens the port exclusively, follows the document's start-up
flow (§5 "Retrieving scanning data", Fig. 5-1): STOP, GET_HEALTH (Protection Stop -> one RESET,
wait 2 ms, ask again; still Error -> a hardware failure naming the port), GET_INFO, start the
motor (SET_MOTOR_PWM for an A2 / accessory board, DTR low for an A1 on its USB adapter), SCAN
and its descriptor; then a reader thread parses nodes (``protocol.NodeParser``), cuts
revolutions on the start flag and turns each clean one into a :class:`Scan` in the ROS
convention (``scan.py``). A revolution during which any byte was dropped is counted in
``corrupt_scans`` and never delivered.

Faults: a port that does not exist, is taken (another process holds it; we open it with an
exclusive lock so two drivers cannot share one device) or refuses us raises
:class:`RplidarError` naming it at ``start()``. Once running, a read that fails (the device was
unplugged) or a stream that goes silent for ``stall_timeout`` sets ``error`` (naming the port),
closes the port and retries the whole start-up with exponential backoff until it works again
or ``stop()`` is called; the stream then resumes.
"""
from __future__ import annotations

import collections
import contextlib
import errno
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from emos.core.retry import Backoff
from emos.errors import EmosError
from emos.ratelimit import RateLimitedLog

from . import protocol as P
from .scan import RevolutionStream, revolution_ranges

__all__ = ["RplidarError", "RplidarHealthError", "Scan", "RplidarDriver"]

_log = logging.getLogger("emos.hardware.rplidar")
_MIN_READ = 512  # bytes: ~1/4 revolution of an A1 at 10 Hz
_POLL_S = 0.02  # what a scan's delivery may wait for its last bytes


class RplidarError(EmosError, RuntimeError):
    """The RPLIDAR on a port cannot be used (the message names the port and why)."""


class RplidarHealthError(RplidarError):
    """GET_HEALTH reported Error (Protection Stop) and a RESET did not clear it."""


@dataclass(frozen=True)
class Scan:
    """One revolution on ``len(ranges)`` beams from ``angle_min`` counter-clockwise."""

    stamp: float  # time.time() when its last node was read
    angle_min: float
    angle_increment: float
    ranges: np.ndarray  # float32 metres, inf = no return
    intensities: np.ndarray  # float32, the quality byte
    scan_time: float  # seconds between this revolution's start and the next one's
    nodes: int  # nodes the revolution had


def _import_serial():
    try:
        import serial
    except ImportError as exc:  # pragma: no cover - the extra is missing
        raise RplidarError("the RPLIDAR driver needs pyserial: pip install 'emos[hardware]'") from exc
    return serial


class RplidarDriver:
    """See the module docstring. ``on_scan(scan)`` (optional) runs in the reader thread."""

    def __init__(self, port: str, baudrate: int = 115200, *, bins: int = 360, range_min: float = 0.15,
                 range_max: float = 12.0, motor_pwm: int = P.DEFAULT_MOTOR_PWM, timeout: float = 1.0,
                 stall_timeout: float = 2.0, reconnect: Backoff | None = None,
                 on_scan: Callable[[Scan], None] | None = None, max_queue: int = 50) -> None:
        if not isinstance(port, str) or not port:
            raise RplidarError(f"RPLIDAR port must be a device path such as /dev/ttyUSB0, got {port!r}")
        if bins < 8:
            raise ValueError(f"RplidarDriver({port}): bins must be >= 8, got {bins}")
        if not 0 <= range_min < range_max:
            raise ValueError(f"RplidarDriver({port}): need 0 <= range_min < range_max, got {range_min}, {range_max}")
        P.motor_pwm_request(motor_pwm)  # validates the PWM
        self.port, self.baudrate = port, int(baudrate)
        self.bins, self.range_min, self.range_max = int(bins), float(range_min), float(range_max)
        self.motor_pwm, self.timeout, self.stall_timeout = motor_pwm, float(timeout), float(stall_timeout)
        # retry forever (stop() ends it): the cap keeps a replugged device found within a second
        self.reconnect = reconnect or Backoff(base=0.05, factor=2.0, cap=1.0, timeout=1e12)
        self.on_scan = on_scan
        self._serial = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._cond = threading.Condition()
        self._scans: collections.deque[Scan] = collections.deque(maxlen=max_queue)
        self._ratelog = RateLimitedLog(_log, interval=10.0)
        self.info: P.DeviceInfo | None = None
        self.health: P.Health | None = None
        self.error: str | None = None  # set while the device is lost or failing
        self.scans = 0
        self.corrupt_scans = 0
        self.bytes_dropped = 0
        self.resyncs = 0
        self.reconnects = 0
        self.disconnects = 0

    # -- public -----------------------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self._serial is not None and self.error is None

    def start(self) -> P.DeviceInfo:
        """Open, check and start scanning; raises :class:`RplidarError` naming the port."""
        self._stop.clear()
        info = self._bring_up()
        self._thread = threading.Thread(target=self._run, name=f"rplidar-{self.port}", daemon=True)
        self._thread.start()
        return info

    def stop(self) -> None:
        """Stop the reader, the scan and the motor; close the port."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        ser = self._serial
        if ser is not None:
            with contextlib.suppress(Exception):
                ser.write(P.request(P.CMD_STOP))
                time.sleep(0.002)  # >= 1 ms before the next request (§4 STOP)
                ser.write(P.motor_pwm_request(0))
                with contextlib.suppress(OSError):
                    ser.dtr = True  # A1: DTR high stops the motor
            self._close()

    def get_scans(self) -> list[Scan]:
        """Every scan delivered since the last call (oldest first)."""
        with self._cond:
            out = list(self._scans)
            self._scans.clear()
            return out

    def wait_scan(self, timeout: float) -> Scan | None:
        """The next scan (the oldest undelivered one), or None after ``timeout`` seconds."""
        with self._cond:
            if not self._scans:
                self._cond.wait(timeout)
            return self._scans.popleft() if self._scans else None

    # -- bring-up -----------------------------------------------------------------------------------
    def _open(self):
        serial = _import_serial()
        try:
            return serial.Serial(self.port, self.baudrate, timeout=0.05, write_timeout=self.timeout, exclusive=True)
        except serial.SerialException as exc:
            code = getattr(exc, "errno", None)
            text = str(exc)
            if code == errno.ENOENT or "No such file" in text:
                why = "does not exist (is the lidar plugged in? check the path, e.g. /dev/ttyUSB0 or /dev/serial/by-id/...)"
            elif code in (errno.EAGAIN, errno.EBUSY) or "lock" in text:
                why = "is taken by another process (close the other program using it)"
            elif code == errno.EACCES or "Permission denied" in text:
                why = "cannot be opened: permission denied (add the user to the dialout group)"
            else:
                why = f"cannot be opened: {text}"
            raise RplidarError(f"RPLIDAR port {self.port} {why}") from exc

    def _read_response(self, ser, expected: P.Descriptor, what: str) -> bytes:
        """Wait for ``expected``'s descriptor (dropping bytes before it) and its data."""
        deadline = time.monotonic() + self.timeout
        buf = b""
        while time.monotonic() < deadline:
            buf += ser.read(max(1, ser.in_waiting))
            at = P.find_descriptor(buf, expected)
            if at >= 0:
                need = at + P.DESCRIPTOR_SIZE + (expected.length if expected.mode == P.MODE_SINGLE else 0)
                while len(buf) < need and time.monotonic() < deadline:
                    buf += ser.read(need - len(buf))
                if len(buf) >= need:
                    self.bytes_dropped += at
                    return buf[at + P.DESCRIPTOR_SIZE:need]
        raise RplidarError(f"RPLIDAR on {self.port}: no {what} response within {self.timeout:.1f} s "
                           f"(got {len(buf)} bytes: {buf[:16].hex(' ')}); is it an RPLIDAR at {self.baudrate} baud?")

    def _request(self, ser, cmd: int, expected: P.Descriptor, what: str) -> bytes:
        ser.reset_input_buffer()
        ser.write(P.request(cmd))
        return self._read_response(ser, expected, what)

    def _bring_up(self) -> P.DeviceInfo:
        ser = self._open()
        try:
            ser.write(P.request(P.CMD_STOP))  # a device left scanning by a previous run
            time.sleep(0.01)
            health = P.Health.decode(self._request(ser, P.CMD_GET_HEALTH, P.HEALTH_DESCRIPTOR, "GET_HEALTH"))
            if health.status == P.HEALTH_ERROR:  # Fig. 5-1: RESET, wait 2 ms, ask again
                _log.warning("RPLIDAR on %s: health Error (code 0x%04X): sending RESET", self.port, health.error_code)
                ser.write(P.request(P.CMD_RESET))
                time.sleep(0.05)
                health = P.Health.decode(self._request(ser, P.CMD_GET_HEALTH, P.HEALTH_DESCRIPTOR, "GET_HEALTH"))
                if health.status == P.HEALTH_ERROR:
                    raise RplidarHealthError(f"RPLIDAR on {self.port}: hardware failure, health status Error "
                                             f"(Protection Stop), error code 0x{health.error_code:04X}, still after a RESET")
            if health.status == P.HEALTH_WARNING:
                _log.warning("RPLIDAR on %s: health Warning (code 0x%04X)", self.port, health.error_code)
            info = P.DeviceInfo.decode(self._request(ser, P.CMD_GET_INFO, P.INFO_DESCRIPTOR, "GET_INFO"))
            try:
                ser.dtr = False  # A1 on its USB adapter: DTR low turns the motor
            except OSError:
                pass  # a port without modem lines (a pty, a bare UART): the PWM request is the way
            ser.write(P.motor_pwm_request(self.motor_pwm))
            time.sleep(0.002)
            ser.reset_input_buffer()
            ser.write(P.request(P.CMD_SCAN))
            self._read_response(ser, P.SCAN_DESCRIPTOR, "SCAN")
        except RplidarError:
            with contextlib.suppress(Exception):
                ser.close()
            raise
        except (OSError, P.RplidarProtocolError, Exception) as exc:  # noqa: BLE001 - pyserial's errors name nothing
            with contextlib.suppress(Exception):
                ser.close()
            raise RplidarError(f"RPLIDAR on {self.port}: start-up failed: {exc}") from exc
        self._serial, self.health, self.info = ser, health, info
        _log.info("RPLIDAR on %s: model 0x%02X firmware %s hardware %d serial %s, scanning", self.port, info.model,
                  info.firmware, info.hardware, info.serial_hex)
        return info

    def _close(self) -> None:
        ser, self._serial = self._serial, None
        if ser is not None:
            with contextlib.suppress(Exception):
                ser.close()

    # -- the reader -----------------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._stream()
            except Exception as exc:  # noqa: BLE001 - any read failure is a lost device here
                if self._stop.is_set():
                    return
                self.error = f"RPLIDAR on {self.port}: device lost ({exc}); reconnecting"
                self.disconnects += 1
                _log.error("%s", self.error)
                self._close()
                self._reconnect()

    def _stream(self) -> None:
        ser = self._serial
        if ser is None:
            raise RplidarError("port closed")
        stream = RevolutionStream()
        parser = stream.parser
        last_node = time.monotonic()
        last_start: float | None = None
        while not self._stop.is_set():
            # Let a few hundred bytes gather between reads (one wake-up per 20 ms, not one per
            # burst the device sends): the parser's cost is per call more than per byte. With
            # nothing waiting, a blocking 1-byte read (50 ms timeout) sees a hang-up at once.
            n = ser.in_waiting
            if n < _MIN_READ:
                self._stop.wait(_POLL_S)
                n = ser.in_waiting
            data = ser.read(n if n else 1)
            now = time.monotonic()
            if not data:
                if now - last_node > self.stall_timeout:
                    raise RplidarError(f"no measurement for {self.stall_timeout:.1f} s")
                continue
            before, resyncs_before, nodes_before = parser.dropped, parser.resyncs, parser.nodes
            revolutions = stream.feed(data)
            if parser.dropped != before:
                self.bytes_dropped += parser.dropped - before
                self.resyncs += parser.resyncs - resyncs_before
                self._ratelog.warning(("dropped", self.port), "RPLIDAR on %s: dropped %d byte(s) out of sync (resync)",
                                      self.port, parser.dropped - before)
            if parser.nodes == nodes_before:
                continue
            last_node = now
            if self.error is not None:
                _log.info("RPLIDAR on %s: stream resumed", self.port)
                self.error = None
            for rev in revolutions:
                scan_time = 0.0 if last_start is None else now - last_start
                last_start = now
                if not rev.clean:
                    self.corrupt_scans += 1
                    continue
                self._deliver(rev.nodes, scan_time)

    def _deliver(self, nodes: P.Nodes, scan_time: float) -> None:
        ranges, intensities = revolution_ranges(nodes, self.bins, self.range_min, self.range_max)
        scan = Scan(stamp=time.time(), angle_min=-np.pi, angle_increment=2.0 * np.pi / self.bins, ranges=ranges,
                    intensities=intensities, scan_time=scan_time, nodes=len(nodes))
        self.scans += 1
        if self.on_scan is not None:
            self.on_scan(scan)
        with self._cond:
            self._scans.append(scan)
            self._cond.notify_all()

    def _reconnect(self) -> None:
        failures = 0
        while not self._stop.is_set():
            try:
                self._bring_up()
            except RplidarError as exc:
                failures += 1
                self.error = f"RPLIDAR on {self.port}: device lost; reconnecting (attempt {failures}: {exc})"
                self._ratelog.warning(("reconnect", self.port), "RPLIDAR on %s: reconnect attempt %d failed: %s",
                                      self.port, failures, exc)
                self._stop.wait(self.reconnect.delay(failures))
                continue
            self.reconnects += 1
            _log.info("RPLIDAR on %s: reconnected after %d failed attempt(s)", self.port, failures)
            return
