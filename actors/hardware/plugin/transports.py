"""How a robot plugin reaches its device: serial (pyserial), UDP, TCP, or a driver session.

Every transport has the same small surface, which is all :class:`~.component.RobotPlugin` uses:
``open()`` (raises :class:`DeviceError` naming the device), ``close()``, ``write(bytes)`` (the
``perf_counter`` time the bytes were handed over, ``None`` if the link is down), ``lost`` (why
the link is down, naming the device; ``None`` while up), ``reconnect()`` (one rung of the
caller's ladder) and ``take()`` (the bytes received since the last call, in order). Byte
transports read in a thread of their own so a frame is parsed as soon as it is complete; the
plugin's decoders run in the component's thread, on what ``take()`` returns.

:class:`SessionTransport` is the "vendor SDK callback" kind: the device's own driver (an SDK, or
our RPLIDAR and Feetech drivers, which follow request/response flows of their own) owns the port;
the plugin polls it for decoded items and it reports ``lost`` and reconnects by itself.
"""
from __future__ import annotations

import collections
import errno
import socket
import threading
import time
from collections.abc import Callable
from typing import Any, ClassVar

from emos.errors import EmosError

__all__ = ["DeviceError", "Transport", "SerialTransport", "UdpTransport", "TcpTransport", "SessionTransport",
           "serial_open_error"]


class DeviceError(EmosError, OSError):
    """A device cannot be opened or was lost (the message names it: port, address, SDK)."""


def serial_open_error(device: str, port: str, exc: BaseException) -> str:
    """Why ``port`` of ``device`` cannot be opened, in words a robot's owner can act on."""
    text = str(exc)
    err = getattr(exc, "errno", None)
    if err == errno.ENOENT or "No such file" in text:
        return f"{device} port {port!r} does not exist (is the device's USB cable plugged in? check ls /dev/ttyUSB* /dev/ttyACM*)"
    if err in (errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK) or "exclusively lock" in text or "busy" in text.lower():
        return f"{device} port {port!r} is taken by another process (close it, or check lsof {port})"
    if err == errno.EACCES or "Permission denied" in text:
        return f"{device} port {port!r}: permission denied (add the user to the dialout group)"
    return f"{device} port {port!r} cannot be opened: {text}"


class Transport:
    """The common surface (module docstring). ``device`` names the device in every message."""

    kind: ClassVar[str] = "?"

    def __init__(self, device: str) -> None:
        self.device = device
        self.lost: str | None = None
        self._rx: collections.deque[bytes] = collections.deque()
        self._closing = threading.Event()
        self._reader: threading.Thread | None = None
        self._wlock = threading.Lock()

    @property
    def address(self) -> str:
        """Where the device is (a port path, host:port): what ``emos robot inspect`` shows."""
        return ""

    def describe(self) -> dict[str, Any]:
        return {"kind": self.kind, "device": self.device, "address": self.address}

    def open(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        self._closing.set()
        self._close_handle()
        if self._reader is not None and self._reader is not threading.current_thread():
            self._reader.join(timeout=2.0)
        self._reader = None

    def _close_handle(self) -> None:
        pass

    def reconnect(self) -> bool:
        """One rung of the caller's ladder: close what is left, open again. True when up."""
        self.close()
        try:
            self.open()
        except DeviceError as exc:
            self.lost = str(exc)
            return False
        return True

    def take(self) -> bytes:
        """Everything received since the last call (an empty bytes when nothing came)."""
        parts = []
        while self._rx:
            parts.append(self._rx.popleft())
        return b"".join(parts)

    def write(self, data: bytes) -> float | None:
        if self.lost is not None:
            return None
        try:
            with self._wlock:
                self._write(data)
            return time.perf_counter()
        except Exception as exc:  # noqa: BLE001 - SerialException, OSError, termios.error: all mean "gone"
            self._mark_lost(exc)
            return None

    def force_write(self, data: bytes) -> bool:
        """Write even on a link marked lost (a last stop to a device that may still listen)."""
        try:
            with self._wlock:
                self._write(data)
            return True
        except Exception:  # noqa: BLE001 - unreachable: nothing more to do
            return False

    def _write(self, data: bytes) -> None:
        raise NotImplementedError

    def _mark_lost(self, exc: BaseException | str) -> None:
        if self.lost is None and not self._closing.is_set():
            self.lost = f"{self.device} {self.address} lost: {exc}"

    def _start_reader(self, read: Callable[[], bytes]) -> None:
        self._closing.clear()

        def loop() -> None:
            while not self._closing.is_set():
                try:
                    data = read()
                except Exception as exc:  # noqa: BLE001 - any failed read means the device is gone
                    self._mark_lost(exc)
                    return
                if data:
                    self._rx.append(data)

        self._reader = threading.Thread(target=loop, name=f"emos-transport-{self.device}", daemon=True)
        self._reader.start()


class SerialTransport(Transport):
    """A serial port through pyserial, opened exclusively (two drivers never share a device)."""

    kind = "serial"

    def __init__(self, device: str, port: str, baudrate: int = 115200, *, timeout: float = 0.05,
                 write_timeout: float = 0.5) -> None:
        super().__init__(device)
        if not isinstance(port, str) or not port:
            raise ValueError(f"{device}: port must be a serial device path such as '/dev/ttyUSB0', got {port!r}")
        self.port, self.baudrate, self.timeout, self.write_timeout = port, int(baudrate), timeout, write_timeout
        self._ser: Any = None

    @property
    def address(self) -> str:
        return repr(self.port)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "baudrate": self.baudrate}

    def open(self) -> None:
        try:
            import serial
        except ImportError as exc:  # pragma: no cover - depends on the install
            raise DeviceError(f"{self.device}: serial transports need pyserial: pip install 'emos[hardware]'") from exc
        try:
            ser = serial.Serial(self.port, self.baudrate, timeout=self.timeout, write_timeout=self.write_timeout, exclusive=True)
        except (serial.SerialException, OSError) as exc:
            raise DeviceError(serial_open_error(self.device, self.port, exc)) from exc
        self._ser, self.lost = ser, None
        self._rx.clear()

        def read() -> bytes:
            # One byte (waiting at most the port timeout), then whatever else is there: a frame
            # is handed on as soon as it is complete, not when a buffer has filled.
            data: bytes = ser.read(1)
            waiting = ser.in_waiting if data else 0
            return data + ser.read(waiting) if waiting else data

        self._start_reader(read)

    def _close_handle(self) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except Exception:  # noqa: BLE001 - closing a port that is already gone
                pass

    def _write(self, data: bytes) -> None:
        if self._ser is None:
            raise OSError("port closed")
        self._ser.write(data)

    def flush(self) -> None:
        if self._ser is not None:
            self._ser.flush()


class _SocketTransport(Transport):
    def __init__(self, device: str, host: str, port: int) -> None:
        super().__init__(device)
        if not isinstance(host, str) or not host or not (isinstance(port, int) and 0 < port < 65536):
            raise ValueError(f"{device}: host must be a name or address and port 1..65535, got {host!r}:{port!r}")
        self.host, self.port = host, port
        self._sock: socket.socket | None = None

    @property
    def address(self) -> str:
        return f"{self.kind}://{self.host}:{self.port}"

    def _close_handle(self) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()


class UdpTransport(_SocketTransport):
    """Datagrams to ``host:port``; answers come back to our (ephemeral or ``bind_port``) port."""

    kind = "udp"

    def __init__(self, device: str, host: str, port: int, *, bind_port: int = 0) -> None:
        super().__init__(device, host, port)
        self.bind_port = bind_port

    def open(self) -> None:
        try:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.bind(("", self.bind_port))
            sock.connect((self.host, self.port))  # only datagrams from the device are received
            sock.settimeout(0.05)
        except OSError as exc:
            raise DeviceError(f"{self.device} {self.address} cannot be opened: {exc}") from exc
        self._sock, self.lost = sock, None

        def read() -> bytes:
            try:
                return sock.recv(65536)
            except TimeoutError:
                return b""
            except ConnectionRefusedError:  # ICMP port unreachable: nobody listens yet; keep trying
                time.sleep(0.05)
                return b""

        self._start_reader(read)

    def _write(self, data: bytes) -> None:
        if self._sock is None:
            raise OSError("socket closed")
        try:
            self._sock.send(data)
        except ConnectionRefusedError:
            pass  # UDP: a datagram nobody received is not a dead link


class TcpTransport(_SocketTransport):
    """A TCP stream to ``host:port``; the peer closing it marks the link lost."""

    kind = "tcp"

    def __init__(self, device: str, host: str, port: int, *, connect_timeout: float = 2.0) -> None:
        super().__init__(device, host, port)
        self.connect_timeout = connect_timeout

    def open(self) -> None:
        try:
            sock = socket.create_connection((self.host, self.port), timeout=self.connect_timeout)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # commands go out at once
            sock.settimeout(0.05)
        except OSError as exc:
            raise DeviceError(f"{self.device} {self.address} cannot be reached: {exc}") from exc
        self._sock, self.lost = sock, None

        def read() -> bytes:
            try:
                data = sock.recv(65536)
            except TimeoutError:
                return b""
            if not data:
                raise ConnectionError("closed by the device")
            return data

        self._start_reader(read)

    def _write(self, data: bytes) -> None:
        if self._sock is None:
            raise OSError("socket closed")
        self._sock.sendall(data)


class SessionTransport(Transport):
    """A device reached through its own driver or vendor SDK (module docstring).

    ``start()`` opens it (raising :class:`DeviceError` or the driver's own error, which must name
    the device), ``stop()`` closes it, ``error()`` says why it is down (``None`` while up). The
    driver runs its own reconnect ladder: :meth:`reconnect` calls ``retry()`` (one rung of it, for
    drivers that reconnect only when used) and reports whether the device is back.
    """

    kind = "session"

    def __init__(self, device: str, address: str, *, start: Callable[[], Any], stop: Callable[[], Any],
                 error: Callable[[], str | None], retry: Callable[[], Any] | None = None, kind: str = "serial") -> None:
        super().__init__(device)
        self._address, self._start, self._stop, self._error, self._retry = address, start, stop, error, retry
        self.wire_kind = kind  # what the driver speaks over (shown by `emos robot inspect`)

    @property
    def address(self) -> str:
        return repr(self._address)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "kind": self.wire_kind, "via": "driver session"}

    def open(self) -> None:
        self._start()
        self.lost = None

    def close(self) -> None:
        self._stop()

    def reconnect(self) -> bool:
        if self._retry is not None:
            self._retry()
        self.lost = self._error()
        return self.lost is None

    def poll_lost(self) -> str | None:
        self.lost = self._error()
        return self.lost

    def _write(self, data: bytes) -> None:
        raise DeviceError(f"{self.device}: a driver session takes no raw bytes; call its driver")
