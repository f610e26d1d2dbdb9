"""The Create 2 serial link: open the port, start the OI, stream sensors, send Drive Direct.

Pure of EMOS topics, for scripts and tests that talk to a Create 2 directly; the component
(``component.py``) is a robot plugin on the generic serial transport instead. A
reader thread parses the stream (``protocol.StreamParser``) into a queue of checked frames; a
failed read or write marks the link ``lost`` with the port named, and :meth:`reconnect` tries
to open it again (the caller decides when, on its ladder).
"""
from __future__ import annotations

import collections
import threading
import time
from typing import Any

from ..plugin.transports import DeviceError, serial_open_error
from . import protocol as P
from .odometry import DiffDriveOdometry


class Create2PortError(DeviceError):
    """The serial port of the Create 2 cannot be opened or was lost (the message names it)."""


def _serial() -> Any:
    try:
        import serial
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise Create2PortError("the Create 2 driver needs pyserial: pip install 'emos[hardware]'") from exc
    return serial


class Create2Link:
    """One serial connection to a Create 2 (or its emulator) at ``port``."""

    def __init__(self, port: str, *, baud: int = P.BAUD_RATE, stream_ids: tuple[int, ...] = P.DRIVER_STREAM_IDS) -> None:
        self.port = port
        self.baud = baud
        self.stream_ids = stream_ids
        self.parser = P.StreamParser(expected_ids=stream_ids)
        self.frames: collections.deque[P.SensorFrame] = collections.deque(maxlen=1024)
        self.lost: str | None = None  # why the link is down (names the port), None while up
        self.write_stamps: collections.deque[float] = collections.deque(maxlen=4096)  # perf_counter after each Drive Direct write
        self._ser: Any = None
        self._reader: threading.Thread | None = None
        self._closing = threading.Event()
        self._wlock = threading.Lock()

    # -- open / close ------------------------------------------------------------------------------
    def open(self) -> None:
        """Open the port and start the OI: Start, Safe, then the sensor stream (OI spec, Getting
        Started: Start first; Safe so Drive Direct is obeyed with the robot's own cliff and
        wheel-drop protection). Raises :class:`Create2PortError` naming the port."""
        serial = _serial()
        try:
            ser = serial.Serial(self.port, self.baud, timeout=0.05, write_timeout=0.5, exclusive=True)
        except serial.SerialException as exc:
            raise Create2PortError(self._why(exc)) from exc
        self._ser = ser
        self.lost = None
        self._closing.clear()
        self._send(bytes([P.START]) + bytes([P.SAFE]) + P.stream_request(self.stream_ids))
        self._reader = threading.Thread(target=self._read_loop, args=(ser,), name=f"create2-reader-{self.port}", daemon=True)
        self._reader.start()

    def _why(self, exc: BaseException) -> str:
        return serial_open_error("Create 2", self.port, exc)

    def close(self, stop_base: bool = True) -> None:
        self._closing.set()
        ser, self._ser = self._ser, None
        if ser is not None:
            if stop_base and self.lost is None:
                try:  # the Create 2 keeps its last command forever: leave it standing still
                    ser.write(P.drive_direct(0, 0) + P.pause_resume(False))
                    ser.flush()
                except Exception:  # noqa: BLE001 - best effort on the way out
                    pass
            try:
                ser.close()
            except Exception:  # noqa: BLE001
                pass
        if self._reader is not None and self._reader is not threading.current_thread():
            self._reader.join(timeout=2.0)
        self._reader = None

    def reconnect(self) -> bool:
        """One rung of the ladder: close what is left, try to open again. True when up."""
        self.close(stop_base=False)
        try:
            self.open()
        except Create2PortError as exc:
            self.lost = str(exc)
            return False
        return True

    # -- I/O ---------------------------------------------------------------------------------------
    def _mark_lost(self, exc: BaseException) -> None:
        if self.lost is None and not self._closing.is_set():
            self.lost = f"Create 2 port {self.port!r} lost: {exc}"

    def _send(self, data: bytes) -> float | None:
        """Write ``data``; the perf_counter time it was handed to the port, None if the link is down."""
        ser = self._ser
        if ser is None or self.lost is not None:
            return None
        try:
            with self._wlock:
                ser.write(data)
            return time.perf_counter()
        except Exception as exc:  # noqa: BLE001 - SerialException, OSError, termios.error: all mean "gone"
            self._mark_lost(exc)
            return None

    def drive_direct(self, right_mm_s: float, left_mm_s: float) -> bool:
        stamp = self._send(P.drive_direct(right_mm_s, left_mm_s))
        if stamp is not None:
            self.write_stamps.append(stamp)
        return stamp is not None

    def try_stop(self) -> bool:
        """Drive Direct (0, 0) even on a link marked lost: True if the bytes were written."""
        ser = self._ser
        if ser is None:
            return False
        try:
            with self._wlock:
                ser.write(P.drive_direct(0, 0))
            return True
        except Exception:  # noqa: BLE001 - unreachable: nothing more to do here
            return False

    def _read_loop(self, ser: Any) -> None:
        while not self._closing.is_set():
            try:
                # One byte (waiting at most the port timeout), then whatever else is there: a
                # frame is parsed as soon as it is complete, not when 512 bytes have piled up.
                data = ser.read(1)
                waiting = ser.in_waiting if data else 0
                if waiting:
                    data += ser.read(waiting)
            except Exception as exc:  # noqa: BLE001
                self._mark_lost(exc)
                return
            if data:
                self.frames.extend(self.parser.feed(data))

    def take_frames(self) -> list[P.SensorFrame]:
        out = []
        while self.frames:
            out.append(self.frames.popleft())
        return out


__all__ = ["Create2Link", "Create2PortError", "DiffDriveOdometry"]
